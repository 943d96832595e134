"""`./run bench`'s summary table: the hop's floor and the corrected p50 goal beside the issue's goals.

Pure Python on made-up latency figures (no node, no timing): what the rows are, not what they measure; and the
lean floor's shaping (the ZVD work alone, `benchmarks/echo_node.py --shape`) against the FIR.
"""

from __future__ import annotations

from benchmarks.summary import GOALS, _latency_rows


def _run(label: str, p50: float, p99: float, cpu_per_msg: float) -> dict:
    return {"label": label, "lost": 0, "p50_us": p50, "p99_us": p99, "node_cpu_pct": 10.0,
            "node_cpu_us_per_msg": cpu_per_msg}


def _rows(lat: dict) -> dict[tuple[str, str], dict]:
    return {(r["figure"], r["baseline"]): r for r in _latency_rows(lat)}


def test_the_shaper_is_set_against_the_echo_with_the_issues_goals_and_against_the_floor_with_the_corrected_one():
    echo, floor = _run("echo (baseline)", 500.0, 2000.0, 400.0), _run("echo, take loop", 400.0, 1000.0, 160.0)
    zvd, none = _run("shaper zvd 8 Hz", 440.0, 1200.0, 190.0), _run("shaper none", 420.0, 1100.0, 180.0)
    hog = [_run("echo (baseline) + hog", 900.0, 5000.0, 400.0), _run("echo, take loop + hog", 450.0, 2000.0, 170.0),
           _run("shaper zvd 8 Hz + hog", 500.0, 2500.0, 200.0)]
    rows = _rows({"runs": [echo, floor, none, zvd], "hog_runs": hog})
    # the issue's goals, against the echo, as before
    p50 = rows[("latency shaper zvd 8 Hz: p50", "echo (baseline) p50")]
    assert p50["goal"] == GOALS["p50"] and "0.5x echo" in p50["goal"] and p50["ratio"] == 440.0 / 500.0
    assert rows[("latency shaper zvd 8 Hz: p99", "echo (baseline) p99")]["goal"] == "<= 0.75x echo"
    cpu = rows[("latency shaper zvd 8 Hz: CPU per message", "echo (baseline) CPU per message")]
    assert cpu["goal"] == "<= 0.5x echo" and cpu["ratio"] == 190.0 / 400.0
    # the floor itself against the echo (what shows the issue's p50 out of reach), with no goal
    assert rows[("latency echo, take loop: p50", "echo (baseline) p50")]["ratio"] == 400.0 / 500.0
    # the shaper against the floor of the same run, with the corrected goal on its p50 only
    on_floor = rows[("latency shaper zvd 8 Hz: p50", "echo, take loop p50")]
    assert on_floor["goal"] == GOALS["p50_floor"] and "1.1x the floor" in on_floor["goal"]
    assert on_floor["ratio"] == 440.0 / 400.0
    assert rows[("latency shaper zvd 8 Hz: CPU per message", "echo, take loop CPU per message")]["goal"] == ""
    assert rows[("latency shaper none: p50", "echo, take loop p50")]["goal"] == ""  # goals are the ZVD hop's
    # the same with the hog, against the floor under the same load
    assert rows[("latency shaper zvd 8 Hz + hog: p50", "echo, take loop + hog p50")]["ratio"] == 500.0 / 450.0
    assert ("latency echo, take loop: p50", "echo, take loop p50") not in rows  # not against itself


def test_a_report_without_the_floor_keeps_the_issues_rows_only():
    rows = _rows({"runs": [_run("echo (baseline)", 500.0, 2000.0, 400.0), _run("shaper zvd 8 Hz", 440.0, 1200.0,
                                                                                  190.0)]})
    assert {b for _, b in rows} == {f"echo (baseline) {x}" for x in ("lost", "p50", "p99", "CPU", "CPU per message")}


def test_the_shaper_is_also_set_against_the_floor_that_does_its_work_and_that_floor_carries_no_issue_goal():
    echo, floor = _run("echo (baseline)", 500.0, 2000.0, 400.0), _run("echo, take loop", 400.0, 1000.0, 160.0)
    zvd, lean = _run("shaper zvd 8 Hz", 440.0, 1200.0, 190.0), _run("floor + ZVD work", 420.0, 1100.0, 170.0)
    rows = _rows({"runs": [echo, floor, zvd, lean], "hog_runs": []})
    on_lean = rows[("latency shaper zvd 8 Hz: p50", "floor + ZVD work p50")]
    assert on_lean["ratio"] == 440.0 / 420.0 and on_lean["goal"] == GOALS["p50_lean"]
    assert rows[("latency shaper zvd 8 Hz: p99", "floor + ZVD work p99")]["goal"] == ""
    # the lean floor is measured against the echo and the floor, with none of the shaper's goals
    assert all(r["goal"] in ("", "0") or r["figure"].startswith("latency shaper") for r in rows.values())
    assert rows[("latency floor + ZVD work: p50", "echo, take loop p50")]["ratio"] == 420.0 / 400.0


def test_the_floor_that_does_the_shapers_work_shapes_as_the_shaper_node_does():
    import numpy as np
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray

    from benchmarks.echo_node import lean_shaping
    from benchmarks.latency_replies import expected_output, ramp
    from benchmarks.latency_targets import lean_zvd_target

    zvd = {"shaper.family": "zvd", "shaper.frequency_hz": 8.0, "shaper.damping_ratio": 0.03}
    shaping, target = lean_shaping("zvd", 8.0, 0.03, 7, 1000.0), lean_zvd_target(7, 1000.0, zvd, timed=False)
    data = ramp(300, 7)
    out = np.array([deserialize_message(shaping.shape(serialize_message(Float64MultiArray(data=row.tolist()))),
                                        Float64MultiArray).data for row in data])
    np.testing.assert_allclose(out, expected_output(target.fir, data), rtol=1e-12, atol=1e-12)
