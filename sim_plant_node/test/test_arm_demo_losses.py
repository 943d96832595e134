"""The arm demo reports lost samples beside the numbers they touch (its tables), and nothing when none."""

from __future__ import annotations

from types import SimpleNamespace

from shaper_nodes.core.lockstep import Gaps
from sim_plant_node.clients.arm_demo import _sums, _table


def row(case: str, move: str, rms: float, lost: str = "") -> dict:
    return {"case": case, "move": move, "residual_rms": rms, "percent": 100.0, "peak_mm": 0.1, "settling_s": 0.2,
            "move_and_settle_s": 1.0, "delay_s": 0.0, "path_deviation_mm": 0.0, "lost": lost}


def test_a_move_with_lost_samples_is_marked_in_both_tables_and_the_others_are_unchanged():
    rows = [row("none", "1. home->rotated", 1.0), row("none", "2. rotated->place", 2.0, "lost 12 samples of /tip_imu"),
            row("fixed", "1. home->rotated", 0.1), row("fixed", "2. rotated->place", 0.2)]
    table = _table(rows)
    assert table[3].startswith("| none | 2. rotated->place (lost 12 samples of /tip_imu) | 2.0000 |")
    assert table[2].startswith("| none | 1. home->rotated | 1.0000 |")
    sums = _sums(rows, ["none", "fixed"], 0.01)
    assert sums[2].startswith("| none (1 move with lost samples) | 3.0000 |")
    assert sums[3].startswith("| fixed | 0.3000 |")


def test_the_losses_line_names_each_stream_and_its_count():
    from sim_plant_node.clients.arm_demo import _losses

    class Reader:
        def __init__(self, holes: bool) -> None:
            self.gaps = {"/tip_imu": Gaps(0.001), "/joint_states": Gaps(0.002)}
            for k in range(1, 11):
                if not (holes and k in (4, 5)):
                    self.gaps["/tip_imu"].add(0.001 * k)
                self.gaps["/joint_states"].add(0.002 * k)

        def describe_lost(self) -> str:
            n = self.gaps["/tip_imu"].lost()
            return f"lost {n} samples of /tip_imu" if n else ""

    assert _losses(SimpleNamespace(lockstep=Reader(False))) == (  # type: ignore[arg-type]
        "Samples lost: none (no gap in the stamps; received: /tip_imu 10, /joint_states 10)")
    line = _losses(SimpleNamespace(lockstep=Reader(True)))  # type: ignore[arg-type]
    assert line.startswith("Samples lost: 2 samples of /tip_imu") and "/tip_imu 8" in line
