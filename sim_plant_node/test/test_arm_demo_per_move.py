"""The arm demo's per-move case: its table (per move and cycle, against the schedule, the learner's last word),
and one learning case a run (each runs its own learner node)."""

from __future__ import annotations

from types import SimpleNamespace

from sim_plant_node.clients.arm_demo import MoveRun, _per_move_table, main


def report(**metrics: float) -> SimpleNamespace:
    return SimpleNamespace(metric_names=list(metrics), metric_values=list(metrics.values()))


def test_the_per_move_table_gives_each_move_its_cycles_its_ratio_to_the_schedule_and_what_the_learner_kept():
    runs = [MoveRun(0, "home->pick", 0.0, 1.0, 2.5), MoveRun(1, "pick->home", 2.5, 1.0, 5.0)]

    def measure(rms: float, settle: float) -> SimpleNamespace:
        return SimpleNamespace(residual_rms=rms, move_and_settle_s=settle)

    nan = float("nan")
    per_move = [[(runs[0], measure(0.040, 1.20), report(move=0.0, M=0.04, iteration=1.0, a1_next=nan, t2_next=nan)),
                 (runs[1], measure(0.100, 1.30), report(move=1.0, M=0.1, iteration=1.0, a1_next=0.5, t2_next=0.05))],
                [(runs[0], measure(0.045, 1.25), report(move=0.0, held=1.0)),
                 (runs[1], measure(0.020, 1.35), report(move=1.0, M=0.02, iteration=2.0, a1_next=0.55, t2_next=0.0502,
                                                        held=0.0))]]
    # the demo's rows name a move as its measure does (the move's name alone)
    rows = [{"case": "scheduled", "move": "home->pick", "residual_rms": 0.04, "move_and_settle_s": 1.2},
            {"case": "scheduled", "move": "pick->home", "residual_rms": 0.10, "move_and_settle_s": 1.3}]
    table = _per_move_table(per_move, rows, 0.01)
    assert "0.0173" in table[0]  # the noise floor in this RMS: sqrt(3) x 0.01
    assert table[2] == "| move | c1 | c2 | last % of scheduled | learner's last report |"
    assert table[4] == "| 1. home->pick residual | 0.0400 | 0.0450 | 112.5 | held at the schedule alone |"
    assert table[5] == "| 2. pick->home residual | 0.1000 | 0.0200 | 20.0 | factor A1 0.550, T2 50.2 ms |"
    assert table[6] == "| 1. home->pick move+settle | 1.200 | 1.250 | 104.2 |  |"
    assert table[7] == "| 2. pick->home move+settle | 1.300 | 1.350 | 103.8 |  |"
    # without the scheduled case: no ratio
    assert _per_move_table(per_move, [], 0.01)[4].endswith("| 0.0450 | - | held at the schedule alone |")


def test_one_learning_case_a_run(capsys):
    assert main(["--cases", "none,scheduled_list,scheduled_list_moves"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "one learning case" in err[0] and "scheduled_list_moves" in err[0]


def test_the_payload_table_labels_a_mode_set_aside_by_its_reason():
    """The drift column of the payload case: a mode outside its band but present since the move's first cycles is
    ``baseline``, one far above every design mode ``above`` (the core's own wording), a rated one outside
    ``outside``."""
    import math as m

    from shaper_nodes.core.identification import ModeFit
    from shaper_nodes.core.identification.drift import Baseline, rate_modes
    from shaper_nodes.core.shaping.families import Mode, design
    from sim_plant_node.clients.arm_payload import Drift, _label

    zv = design("zv", (Mode(2 * m.pi * 4.0, 0.02),))

    def fit(hz: float, zeta: float) -> ModeFit:
        return ModeFit(2 * m.pi * hz, zeta, 0.01, 0.001, 1.0, "fit")

    baseline = Baseline(1)
    baseline.take([fit(4.6, 0.3)])
    labels = []
    for mode, shift in ((fit(4.6, 0.3), None), (fit(9.0, 0.3), 0.3), (fit(4.6, 0.02), None)):
        rating = rate_modes(zv.amplitudes, zv.times, [4.0], [mode], 0.05, baseline, shift)
        assert rating is not None
        text = "cycle 3: " + rating.describe("the shaper the scheduler gave this move", "the move's first cycles")
        labels.append(_label(Drift(3, 0, text, rating.check.mode_hz)))
    assert labels == ["baseline 4.600 Hz", "above 9.000 Hz", "outside 4.600 Hz"]
