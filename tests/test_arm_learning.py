"""The arm-learning reproduction, a few cycles: rows in the issue's schema, the speed-up learned per move
within the limits, every move's state saved and loaded back (ROS-free, the modal schedule: quick)."""

from __future__ import annotations

import json

import pytest

from reproductions import arm_learning
from shaper_nodes.core.learning.moves import move_key, store_from_doc
from sim_plant_node.arm.metrics import SETTLE_TOLERANCE
from sim_plant_node.arm.task import cycle_moves

SCHEMA = {"case", "move", "cycle", "residual_rms", "peak_mm", "settle_s", "move_settle_s", "speed_factor"}


def test_two_cycles_of_the_speed_up_over_the_schedule(tmp_path):
    out = tmp_path / "out"
    path = tmp_path / "rows.json"
    assert arm_learning.main(["--cycles", "2", "--cases", "speedup", "--schedule", "modal", "--no-docs",
                              "--json", str(path), "--out", str(out)]) == 0
    rows = json.loads(path.read_text())["rows"]
    moves = [m.name for m in cycle_moves()]
    assert len(rows) == 2 * len(moves)
    assert all(set(r) >= SCHEMA for r in rows)
    fast = {(r["move"], r["cycle"]): r for r in rows}
    for m in moves:
        # the first cycle runs the schedule at the planned speed; nothing was violated there, so every move
        # was raised by one step, and it is faster
        assert fast[(m, 1)]["speed_factor"] == 1.0
        assert fast[(m, 1)]["peak_mm"] <= 1e3 * SETTLE_TOLERANCE
        assert fast[(m, 2)]["speed_factor"] == pytest.approx(1.1)
        assert fast[(m, 2)]["move_settle_s"] < fast[(m, 1)]["move_settle_s"]
        assert fast[(m, 2)]["velocity_ratio"] <= 1.0 and fast[(m, 2)]["torque_ratio"] <= 1.0
    store, problems = store_from_doc(json.loads((out / "moves_speedup.json").read_text()))
    assert problems == {} and len(store) == len({(m.positions[0].tobytes(), m.positions[-1].tobytes())
                                                  for m in cycle_moves()})
    first = cycle_moves()[0]
    entry = store.get(move_key(first.positions[0], first.positions[-1]))
    assert entry is not None and entry.speed().factor == pytest.approx(1.2)


def test_bad_options_are_refused_with_the_problem_named(capsys):
    for argv, words in ((["--cycles", "0"], "--cycles must be >= 1"), (["--cases", "nope"], "unknown case(s) nope"),
                        (["--noise", "-1"], "--noise must be finite and >= 0")):
        with pytest.raises(SystemExit):
            arm_learning.main(argv)
        assert words in capsys.readouterr().err


def test_a_case_registers_under_its_name():
    @arm_learning.register("test_only")
    def case(ctx, cycles):
        return []

    try:
        assert arm_learning.CASES["test_only"] is case
    finally:
        del arm_learning.CASES["test_only"]
