"""Closed-loop input shaping through the ROS graph: sim plant (loop inside) and shaper as processes, lockstep.

Seed 001's time-delay feedback controller (one joint per real plant frequency, one run) and
seed 002's QFT feedforward-feedback loop on the eight corner plants against open-loop ZV and ZVD.
"""

from __future__ import annotations

import numpy as np
import pytest

from reproductions.closed_loop_cases import DELAY_USED, OMEGA_A, Run002, run_seed001, run_seed002, tdf_interval_from_cli
from reproductions.closed_loop_measures import (
    EVENT_TIME,
    dominant_oscillation,
    event_effect,
    growth,
    residual,
    settle_time,
    settled_window,
    shaper_floor,
    vibration,
)
from shaper_nodes.core.closed_loop.qft import corners, nominal
from shaper_nodes.core.closed_loop.time_delay import exact_step_response

#: allowed excess of the sim's overshoot over the exact continuous one (fraction): the 1 kHz zero-order-hold
#: loop's error is first order in the step (1.13e-3 at 1 ms, halving with the step: test_loops.py), doubled
#: to cover the 100 Hz sampling of the peak in the record
ZOH_OVERSHOOT_TOL = 2e-3

pytestmark = pytest.mark.integration


def test_seed001_time_delay_feedback(start_node, ros_context):
    interval = tdf_interval_from_cli()  # what `loop_design tdf-interval` prints
    assert interval[0] == pytest.approx(3.0) and 4.0 < interval[1] < 6.0
    cases, tr = run_seed001(start_node, ros_context, interval, dwell=30.0)
    names = list(cases)
    y = tr.output
    # w_R = w_A: at 1 without overshoot from 2T on (first sample at or after 2T at 100 Hz)
    assert y[:, 0].max() <= 1.0 + 1e-9
    assert settle_time(tr, 0, tol=1e-9) <= 2 * DELAY_USED + 0.01
    # w_R = 4: stable, with the overshoot of the exact continuous loop (method of steps, no simulator) up to
    # the 1 kHz loop's discretisation error. That exact value is above the paper's "within 20 %" (read off
    # its Fig. 8): 20.64 % for this T (20.65 % for T = pi/9), so 20 % is not reachable with these parameters
    assert growth(tr, 1) < 1e-3
    exact = exact_step_response(OMEGA_A, DELAY_USED, 4.0).overshoot
    assert exact > 0.20
    assert exact - 1e-4 <= y[:, 1].max() - 1.0 <= exact + ZOH_OVERSHOOT_TOL
    # w_R = 2.9 (below w_A): grows
    assert growth(tr, 2) > 2.0
    # the interval's edges: stable just inside, unstable just outside
    for j in (3, 5):
        assert growth(tr, j) < 0.5, names[j]
    for j in (4, 6):
        assert growth(tr, j) > 2.0, names[j]


RUNS = (
    Run002("ffb", "qft_ffb", "zv", {}),
    Run002("zv", "qft_open", "zv", {}),
    Run002("zvd", "qft_open", "zvd", {}),
    Run002("dist_open", "qft_open", "zv", {"loop.disturbance_step": 1.0}),
    Run002("dist_ffb", "qft_ffb", "zv", {"loop.disturbance_step": 1.0}),
    Run002("noise_open", "qft_open", "zv", {"loop.noise_step": 1.0}),
    Run002("noise_ffb", "qft_ffb", "zv", {"loop.noise_step": 1.0}),
)


def test_seed002_zv_with_feedforward_feedback(start_node, ros_context):
    tr = run_seed002(start_node, ros_context, RUNS)
    cs = corners()
    p0 = nominal()
    # two corners (all parameters 0.65 or 1.35 times nominal) have P = P0 (to the 5 digits); two more
    # have the nominal frequency and only another damping ratio (0.21 and 0.048)
    same = np.array([abs(c.k / c.m - p0.k) < 1 and abs(c.c / c.m - p0.c) < 0.01 for c in cs])
    damping_only = np.array([abs(c.k / c.m - p0.k) < 1 for c in cs]) & ~same
    light = damping_only & np.array([c.zeta < p0.zeta for c in cs])
    assert same.sum() == 2 and damping_only.sum() == 2 and light.sum() == 1
    # metric 1 (RMS of x2 - 1 after the shaped step) and metric 2 (residual vibration: the oscillatory part
    # of x2 - 1 after the shaped step, the loop's non-oscillatory settling removed; docs/design/closed_loop.md)
    r_ffb, r_zv, r_zvd = residual(tr["ffb"], "zv")[0], residual(tr["zv"], "zv")[0], residual(tr["zvd"], "zvd")[0]
    ffb, zv, zvd = vibration(tr["ffb"])[0], vibration(tr["zv"])[0], vibration(tr["zvd"])[0]
    # the shaper node discretises 'exact' (closed_loop_cases): P0's own residual after the reference it sent,
    # computed without the sim plant, is zero to rounding (with 'split' it was 0.05 mm)
    assert shaper_floor(tr["zv"]) < 1e-12 and shaper_floor(tr["zvd"]) < 1e-12
    # Fig. 9 against open-loop ZV: a quarter or less on all eight corners, by both metrics. On the two corners
    # equal to P0 to five digits, what is left comes from that rounding: micrometres open loop, the loop
    # removes most of it
    assert np.all(r_ffb <= 0.25 * r_zv), (r_ffb, r_zv)
    assert np.all(ffb <= 0.25 * zv), (ffb, zv)
    assert np.all(r_zv[same] < 1e-5) and np.all(r_ffb[same] < 1e-7), (r_zv, r_ffb)
    # against open-loop ZVD: a quarter or less on the four corners whose frequency differs (both metrics)
    # and, by metric 2, on the damping-only corner with zeta = 0.21 (metric 1 is 0.30 there: the loop's
    # slow creep to the target, not vibration)
    off = ~same & ~damping_only
    assert np.all(r_ffb[off] <= 0.25 * r_zvd[off]), (r_ffb, r_zvd)
    assert np.all(ffb[~same & ~light] <= 0.25 * zvd[~same & ~light]), (ffb, zvd)
    # the damping-only corner with zeta = 0.048 does NOT meet it (0.38 of ZVD): the ZV-shaped step excites
    # the loop's own lightly damped mode (the plant's mode stiffened by the feedback, about 630 rad/s,
    # zeta about 0.1; 0.13 for the continuous controller), which rings after the shaped step; still well
    # below open-loop ZVD
    assert np.all(ffb[light] <= 0.5 * zvd[light]), (ffb, zvd)
    w = settled_window(tr["ffb"])
    (j,) = np.nonzero(light)[0]
    omega, _ = dominant_oscillation(tr["ffb"].output[w, j] - 1.0, 1e-3)
    assert omega > 3 * cs[j].omega_n
    # nor on the two corners equal to P0 to five digits, where ZVD's zero slope makes the rounding's effect
    # second order (1e-11 m) and the loop's is first order: nanometres against picometres, both far below
    # anything a sensor resolves on a 1 m step
    assert np.all(r_zvd[same] < 1e-9)
    # Fig. 10: the loop removes a unit-step output disturbance that stays in the open loop
    assert np.all(event_effect(tr["dist_ffb"]) < 0.25 * event_effect(tr["dist_open"]))
    # and a unit-step measurement noise: what the sensor shows is brought back, while the true output
    # moves by the noise (y / n = -T): the loop cannot tell noise from output
    assert np.all(event_effect(tr["noise_ffb"], "measured") < 0.25 * event_effect(tr["noise_open"], "measured"))
    late = tr["noise_ffb"].t > EVENT_TIME + 0.3
    assert np.allclose(tr["noise_ffb"].output[late], 0.0, atol=0.05)


def test_record_with_lost_loop_samples_is_refused(start_node, ros_context, monkeypatch):
    """A record that missed loop samples is not measured (session 13, H7 loopdet): under load, samples of the
    plant's ~/loop_state were lost on the way to the recorder and the page's metrics came out of a trace with a
    gap (metric 2 blown up to 1e10 mm). A recorder that keeps one sample loses them on every run: each run of
    the case is refused and the reproduction gives up, instead of measuring the gap."""
    import reproductions.closed_loop_cases as cases

    monkeypatch.setattr(cases, "RECORD_DEPTH", 1)
    with pytest.raises(RuntimeError, match=f"loop samples lost in each of {cases.ATTEMPTS} runs"):
        run_seed002(start_node, ros_context, (Run002("zv", "qft_open", "zv", {}),))
