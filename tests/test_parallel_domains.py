"""The ROS domains of parallel test workers (the root conftest.py, pytest-xdist): tests running at once on two
workers never share a domain, and a run without workers takes the domains after its base, as before."""

from __future__ import annotations

import fcntl
import importlib.util
import os
import pathlib

import pytest
from conftest import DOMAIN_LOCKS, DOMAINS, new_domain, release_domain

_spec = importlib.util.spec_from_file_location("root_conftest", pathlib.Path(__file__).resolve().parents[1]
                                               / "conftest.py")
assert _spec is not None and _spec.loader is not None
root = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(root)


@pytest.mark.parametrize("workers", [1, 2, 3, 4, 6, 8, 16])
@pytest.mark.parametrize("base", [0, 60, 197, 250])
def test_no_two_workers_ever_share_a_domain(base, workers):
    taken: dict[int, int] = {}
    for i in range(workers):
        first, stride = root.worker_domains(base, f"gw{i}", workers)
        assert stride >= workers and DOMAINS % stride == 0
        # every domain the worker's tests take, however many (the counter wraps at DOMAINS)
        for n in range(3 * DOMAINS):
            domain = 1 + (first + stride * n) % DOMAINS
            assert 1 <= domain <= DOMAINS
            assert taken.setdefault(domain, i) == i, f"gw{i} and gw{taken[domain]} both take domain {domain}"


def test_without_workers_the_domains_follow_the_base():
    assert root.worker_domains(60, None, 1) == (60, 1)


def test_too_many_workers_are_refused_with_the_limit_named():
    with pytest.raises(pytest.UsageError, match=f"at most {DOMAINS} workers"):
        root.worker_domains(60, "gw0", DOMAINS + 1)


def test_this_process_takes_its_domains_from_its_base_and_stride():
    """What the fixture gives here follows the environment the root conftest.py set for this worker."""
    base, stride = int(os.environ["ROS_DOMAIN_ID"]), int(os.environ["SHAPER_DOMAIN_STRIDE"])
    a, b = new_domain(), new_domain()
    # both of this worker's; b the next after a unless another process on the machine held that one (below)
    assert (a - 1 - base) % stride == 0 and (b - 1 - base) % stride == 0 and a != b
    release_domain(a)
    release_domain(b)
    if os.environ.get("PYTEST_XDIST_WORKER"):
        assert stride >= int(os.environ["PYTEST_XDIST_WORKER_COUNT"])
    else:
        assert stride == 1


def test_a_domain_another_process_holds_is_passed_over_and_released_at_the_end():
    """Test sessions started apart on one machine (another checkout's, with a base of its own) never share a domain:
    each takes its domain's lock file (flock) while its test runs, and passes over one held elsewhere. The other
    holder here is a second open file description of the lock (flock's locks belong to it, as another process's
    would)."""
    stride = int(os.environ.get("SHAPER_DOMAIN_STRIDE", "1"))
    mine = new_domain()
    after = 1 + (mine - 1 + stride) % DOMAINS
    with open(DOMAIN_LOCKS / f"{after}.lock", "a") as other:
        fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)  # held by "another process"
        nxt = new_domain()
        assert nxt != after and (nxt - after) % DOMAINS % stride == 0, (mine, after, nxt)
        with pytest.raises(BlockingIOError), open(DOMAIN_LOCKS / f"{nxt}.lock", "a") as probe:
            fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)  # this process holds its domains until the test ends
    release_domain(nxt)
    release_domain(mine)
    with open(DOMAIN_LOCKS / f"{nxt}.lock", "a") as probe:
        fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)  # released: free for another session
