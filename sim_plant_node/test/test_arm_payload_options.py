"""The arm demo's payload case options: its learner (LIST or MRILC per move) and whether the learner is told the
payload (``--payload-told``, MRILC only); refused with one line before any node starts."""

from __future__ import annotations

import argparse

from sim_plant_node.clients.arm_demo import main
from sim_plant_node.clients.arm_payload import CASE, add_arguments, check_args


def parse(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    p.add_argument("--list-cycles", type=int, default=8)
    add_arguments(p)
    return p.parse_args(list(argv))


def test_the_payload_case_takes_mrilc_and_tells_it_the_payload_only_with_mrilc(capsys):
    assert parse().payload_learner == "list" and parse().payload_told is False
    assert check_args(parse("--payload-learner", "mrilc", "--payload-told"), [CASE]) == ""
    assert check_args(parse("--payload-learner", "mrilc"), [CASE]) == ""
    assert check_args(parse("--payload-told"), [CASE]) == "--payload-told goes with --payload-learner mrilc"
    assert check_args(parse("--payload-told"), ["none"]) == ""  # the case not run: nothing checked
    # a namespace without the options (as a test's own) is LIST, not told
    assert check_args(argparse.Namespace(payload_cycle=3, payload_mass=4.5, list_cycles=8), [CASE]) == ""
    assert main(["--cases", "none,payload", "--payload-told"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--payload-told goes with --payload-learner mrilc" in err[0], err
