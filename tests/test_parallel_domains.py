"""The ROS domains of parallel test workers (the root conftest.py, pytest-xdist): tests running at once on two
workers never share a domain, and a run without workers takes the domains after its base, as before."""

from __future__ import annotations

import importlib.util
import os
import pathlib

import pytest
from conftest import DOMAINS, new_domain

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
    assert (a - 1 - base) % stride == 0 and (b - a) % DOMAINS == stride % DOMAINS
    if os.environ.get("PYTEST_XDIST_WORKER"):
        assert stride >= int(os.environ["PYTEST_XDIST_WORKER_COUNT"])
    else:
        assert stride == 1
