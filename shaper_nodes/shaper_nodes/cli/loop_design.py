"""``loop_design``: design tools for closed-loop input shaping (seeds 001 and 002), no ROS needed.

Subcommands (``loop_design SUBCOMMAND --help`` for the options)::

    loop_design tdf-interval --omega-a RAD_S --delay S      stable w_R interval (seed 001, eq. 27)
                 [--max-overshoot PCT]                  ... and where the exact overshoot is <= PCT
    loop_design tdf-step --omega-a RAD_S --delay S --omega-r RAD_S [--band 0.02]
                                                            stable?, overshoot, peak and settling time
    loop_design tdf-select --omega-r RAD_S --delay S        range of w_A for a plant (eqs. 28-30)
    loop_design tdf-plot --figure {3,4,6} --out FILE.png    analogues of seed 001 Figs. 3, 4, 6
    loop_design qft-table [--design ffb|fb|open]            |M - Y/R| per corner plant and frequency
    loop_design qft-plot --figure {6,7,8} --out FILE.png    analogues of seed 002 Figs. 6-8

Frequencies in rad/s, times in s. ``--json`` prints one JSON document. Bad input prints a
message naming the problem on stderr and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from shaper_nodes.core.closed_loop import qft
from shaper_nodes.core.closed_loop import time_delay as td
from shaper_nodes.core.closed_pipe import survives_closed_pipe

from .common import Parser, UsageError, number, run, text_table

PROG = "loop_design"


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog=PROG, description="Closed-loop input shaping design: time-delay feedback (seed 001)"
                                            " and QFT model matching (seed 002).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    pos = lambda what: number(what, positive=True)  # noqa: E731

    p = sub.add_parser("tdf-interval", help="stable interval of the real plant frequency w_R (eq. 27)")
    p.add_argument("--omega-a", type=pos("--omega-a (rad/s)"), required=True, help="assumed frequency w_A, rad/s")
    p.add_argument("--delay", type=pos("--delay (s)"), required=True, help="delay time T, s")
    p.add_argument("--k-max", type=int, default=8, help="change points listed up to this k (default %(default)s)")
    p.add_argument("--max-overshoot", type=pos("--max-overshoot (%)"), metavar="PCT",
                   help="also give the w_R inside the stable interval where the exact step overshoot is <= PCT %%")
    p.add_argument("--grid", type=int, default=41,
                   help="points of the overshoot scan over the stable interval (default %(default)s)")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("tdf-step", help="stability, exact step overshoot, peak time and settling time for one w_R")
    p.add_argument("--omega-a", type=pos("--omega-a (rad/s)"), required=True, help="assumed frequency w_A, rad/s")
    p.add_argument("--delay", type=pos("--delay (s)"), required=True, help="delay time T, s")
    p.add_argument("--omega-r", type=pos("--omega-r (rad/s)"), required=True, help="real plant frequency w_R, rad/s")
    p.add_argument("--band", type=pos("--band"), default=td.DEFAULT_BAND,
                   help="settling band, a fraction of the step (default %(default)s: 2 %%)")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("tdf-select", help="w_A to choose for a plant w_R and delay T (eqs. 28-30)")
    p.add_argument("--omega-r", type=pos("--omega-r (rad/s)"), required=True, help="real (estimated) w_R, rad/s")
    p.add_argument("--delay", type=pos("--delay (s)"), required=True, help="delay time T, s")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("tdf-plot", help="seed 001 Fig. 3 (change points), 4 (stable region), 6 (bound vs w_A)")
    p.add_argument("--figure", type=int, choices=(3, 4, 6), required=True)
    p.add_argument("--omega-a", type=pos("--omega-a (rad/s)"), default=3.0, help="w_A for Figs. 3, 4 (default 3)")
    p.add_argument("--delay", type=pos("--delay (s)"), default=0.5, help="T for Fig. 6 (default 0.5)")
    p.add_argument("--omega-r", type=pos("--omega-r (rad/s)"), default=3.0, help="w_R marked in Fig. 6 (default 3)")
    p.add_argument("--delay-max", type=pos("--delay-max (s)"), default=6.0, help="T axis of Figs. 3, 4 (default 6)")
    p.add_argument("--out", required=True, help="output image (.png)")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("qft-table", help="model matching |M - Y/R| per corner plant and working frequency")
    p.add_argument("--design", choices=qft.DESIGNS, default="ffb",
                   help="ffb (feedforward-feedback, gain 166.7), fb (feedback, 234.4) or open (default ffb)")
    p.add_argument("--gain", type=pos("--gain"), help="controller gain K of eq. (10) (default: the paper's)")
    p.add_argument("--delta", type=pos("--delta"), default=qft.DELTA_M, help="delta_m (default 0.1)")
    p.add_argument("--frequencies", type=pos("--frequencies (rad/s)"), nargs="+",
                   default=list(qft.WORKING_FREQUENCIES), help="working frequencies, rad/s")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("qft-plot", help="seed 002 Fig. 6 (templates, bounds, L0), 7 (|G|), 8 (|Y/R| and |P|)")
    p.add_argument("--figure", type=int, choices=(6, 7, 8), required=True)
    p.add_argument("--out", required=True, help="output image (.png)")
    p.add_argument("--json", action="store_true")
    return parser


# ------------------------------------------------------------------------------------------------ seed 001


def _cmd_tdf_interval(args: argparse.Namespace) -> str:
    si = td.stable_interval(args.omega_a, args.delay)
    gains = td.ppusmd_gains(args.omega_a, args.delay)
    pts = [x for x in td.change_points(args.omega_a, args.delay, args.k_max)]
    doc: dict[str, Any] = {
        "omega_a": args.omega_a, "delay": args.delay, "gains": list(gains),
        "stable_interval": [si.lower, si.upper], "upper_k": si.upper_k,
        "change_points": [{"k": x.k, "phi": x.phi, "omega_r": x.omega_r} for x in pts]}
    oi = None
    if args.max_overshoot is not None:
        oi = td.overshoot_interval(args.omega_a, args.delay, args.max_overshoot / 100.0, grid=args.grid)
        doc["overshoot_limited"] = {
            "max_overshoot_percent": args.max_overshoot,
            "intervals": [[g.low, g.high] for g in oi.segments],
            "edges": [[g.low_edge, g.high_edge] for g in oi.segments],
            "scan": [{"omega_r": w, "overshoot_percent": 100 * lo,
                      "overshoot_bound_percent": None if math.isinf(hi) else 100 * hi, "class": c}
                     for w, lo, hi, c in oi.scan]}
    if args.json:
        return json.dumps(doc, indent=2)
    out = [f"w_A = {args.omega_a:g} rad/s, T = {args.delay:.6g} s (w_A T = {args.omega_a * args.delay:.5g} rad)",
           f"gains A0 = {gains[0]:.6g}, A1 = {gains[1]:.6g}, A2 = {gains[2]:.6g}", "",
           f"stable for {si.lower:.6g} <= w_R <= {si.upper:.6g} rad/s (eq. 27; upper bound from k = {si.upper_k})"]
    if oi is not None:
        out.append(_overshoot_lines(oi))
    out += ["", "possible changes of stability (eq. 15; k = 0 is w_R = w_A, eq. 17):",
           text_table(("k", "phi (rad/s)", "w_R (rad/s)"), [(x.k, f"{x.phi:.5g}", f"{x.omega_r:.6g}") for x in pts])]
    return "\n".join(out)


_EDGE = {"stability": "the stability edge", "overshoot": "overshoot = limit",
         "horizon": "overshoot not bounded beyond (horizon)"}


def _overshoot_lines(oi: td.OvershootInterval) -> str:
    pct = f"{100 * oi.max_overshoot:g} %"
    if not oi.segments:
        return (f"overshoot <= {pct} (exact step response): nowhere in the stable interval"
                f" (smallest on the {len(oi.scan)}-point scan: {100 * min(x[1] for x in oi.scan):.4g} %)")
    parts = [f"{g.low:.6g} <= w_R <= {g.high:.6g} rad/s (ends: {_EDGE[g.low_edge]}; {_EDGE[g.high_edge]})"
             for g in oi.segments]
    return f"overshoot <= {pct} (exact step response) for " + ", and ".join(parts)


def _cmd_tdf_step(args: argparse.Namespace) -> str:
    perf = td.step_performance(args.omega_a, args.delay, args.omega_r, band=args.band)
    r, si = perf.response, perf.interval
    sampled_stable = perf.growth_rate < 0
    doc = {"omega_a": args.omega_a, "delay": args.delay, "omega_r": args.omega_r, "band": args.band,
           "stable_interval": [si.lower, si.upper], "in_stable_interval": perf.in_stable_interval,
           "growth_rate": perf.growth_rate, "sampled_stable": sampled_stable,
           "overshoot_percent": 100 * r.overshoot, "peak": r.peak, "peak_time": r.peak_time,
           "peak_captured": r.peak_captured, "settling_time": r.settling_time, "settled": r.settled,
           "horizon": r.horizon, "accuracy_limited": r.accuracy_limited, "tail_deviation": r.tail_deviation,
           "rounding_error": r.rounding_error}
    if args.json:
        return json.dumps(doc, indent=2)
    where = (f"inside the stable interval {si.lower:.6g} <= w_R <= {si.upper:.6g} rad/s of eq. (27)"
             if perf.in_stable_interval else
             f"OUTSIDE the stable interval {si.lower:.6g} <= w_R <= {si.upper:.6g} rad/s of eq. (27)")
    check = (f"sampled-data check: {'decays' if sampled_stable else 'GROWS'} at {perf.growth_rate:+.4g} /s"
             " (slowest pole, 100 samples per T)")
    verdict = "stable" if perf.in_stable_interval and sampled_stable else (
        "UNSTABLE" if not (perf.in_stable_interval or sampled_stable) else
        "the checks disagree: w_R is at or next to an edge of eq. (27), where the sampled loop's edge differs a little")
    out = [f"w_A = {args.omega_a:g} rad/s, T = {args.delay:.6g} s, w_R = {args.omega_r:g} rad/s: {verdict}",
           f"  {where}; {check}",
           f"exact step response (method of steps) over {r.horizon:.4g} s ({round(r.horizon / args.delay)} intervals"
           f" of T{'; longer would pass the rounding-error limit' if r.accuracy_limited else ''}):"]
    if r.peak_captured:
        scope = "the peak for all t: by the end of the horizon |y - 1| stays below it and no longer grows"
    elif math.isfinite(r.overshoot_bound):
        scope = f"over the horizon; for all t it is at most {100 * r.overshoot_bound:.4g} %"
    else:
        scope = "over the horizon only: the response does not decay within it"
    if r.overshoot > 1e-9:
        out.append(f"  overshoot {100 * r.overshoot:.4f} % at t = {r.peak_time:.5g} s (peak {r.peak:.6g}; {scope})")
    else:
        out.append(f"  no overshoot (largest output {r.peak:.10g}; {scope})")
    if r.settled:
        out.append(f"  settling time ({100 * args.band:g} % band) {r.settling_time:.5g} s")
    else:
        out.append(f"  does NOT settle into the {100 * args.band:g} % band within the {r.horizon:.4g} s horizon"
                   f" (|y - 1| up to {r.tail_deviation:.3g} near its end)"
                   + (f"; the slowest pole's time constant is {-1 / perf.growth_rate:.3g} s" if sampled_stable else ""))
    return "\n".join(out)


def _cmd_tdf_select(args: argparse.Namespace) -> str:
    ranges = td.assumed_frequency_range(args.omega_r, args.delay)
    rows: list[dict[str, Any]] = []
    for rng in ranges:
        ends = []
        for wa in (rng.low, rng.high):
            try:
                ends.append(td.stable_interval(wa, args.delay).upper if wa > 0 else float("nan"))
            except td.TimeDelayError:
                ends.append(float("nan"))
        # which w_A of the range keep w_R inside its stable interval, and which gives the largest margin
        grid = np.linspace(rng.low, rng.high, 401)[1:] if rng.low == 0 else np.linspace(rng.low, rng.high, 401)
        ups = np.array([_upper(float(wa), args.delay) for wa in grid])
        ok = (grid <= args.omega_r) & (ups >= args.omega_r)
        # two-sided margin: how far (as a ratio) w_R is from both edges w_A and the upper bound
        with np.errstate(divide="ignore", invalid="ignore"):
            margin = np.minimum(args.omega_r / grid, ups / args.omega_r)
        best = int(np.nanargmax(np.where(ok, margin, np.nan))) if ok.any() else None
        rows.append({"k": rng.k, "omega_a_low": rng.low, "omega_a_high": rng.high,
                     "upper_bound_at_low": ends[0], "upper_bound_at_high": ends[1],
                     "stable_omega_a": [float(grid[ok].min()), float(grid[ok].max())] if ok.any() else None,
                     "best_omega_a": None if best is None else float(grid[best]),
                     "best_upper_bound": None if best is None else float(ups[best]),
                     "best_margin": None if best is None else float(margin[best])})
    if args.json:
        return json.dumps({"omega_r": args.omega_r, "delay": args.delay, "ranges": rows}, indent=2)
    out = [f"w_R = {args.omega_r:g} rad/s, T = {args.delay:g} s: choose w_A in (eqs. 28-30)",
           text_table(("k", "w_A from", "w_A to", "upper w_R bound there (from)", "(to)"),
                  [(r["k"], f"{r['omega_a_low']:.5g}", f"{r['omega_a_high']:.5g}",
                    *("-" if math.isnan(b) else f"{b:.5g}"
                      for b in (r["upper_bound_at_low"], r["upper_bound_at_high"])))
                   for r in rows]),
           "then check the margin with tdf-interval (the lower bound is always w_R = w_A)."]
    for r in rows:
        if r["stable_omega_a"] is None:
            out.append(f"k = {r['k']}: no w_A of this range keeps w_R = {args.omega_r:g} rad/s stable")
        else:
            lo, hi = r["stable_omega_a"]
            out.append(f"k = {r['k']}: w_R = {args.omega_r:g} rad/s is stable for w_A in about [{lo:.4g}, {hi:.4g}]"
                       f" rad/s; the largest margin to both edges, a factor {r['best_margin']:.4g}, at"
                       f" w_A = {r['best_omega_a']:.4g} rad/s (stable {r['best_omega_a']:.4g} <= w_R <="
                       f" {r['best_upper_bound']:.5g} rad/s)")
    return "\n".join(out)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out: str) -> None:
    try:
        fig.savefig(out)
    except (OSError, ValueError) as exc:
        raise UsageError(f"cannot write {out!r}: {exc}") from None
    finally:
        _plt().close(fig)


def _cmd_tdf_plot(args: argparse.Namespace) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=110)
    wa = args.omega_a
    if args.figure in (3, 4):
        ts = np.linspace(0.02, args.delay_max, 900)
        curves: dict[int, list[float]] = {}
        for t in ts:
            try:
                pts = {x.k: x.omega_r for x in td.change_points(wa, float(t), 6) if x.k > 0}
            except td.TimeDelayError:
                pts = {}
            for k in range(1, 7):
                curves.setdefault(k, []).append(pts.get(k, np.nan))
        if args.figure == 3:
            for k, v in curves.items():
                ax.plot(ts, v, label=f"k = {k}", lw=1)
            ax.axhline(wa, color="k", lw=1, label="w_R = w_A (eq. 17)")
            ax.set_title(f"Possible changes of stability, eq. (15), w_A = {wa:g} rad/s (seed 001 Fig. 3)")
        else:
            up = np.array([_upper(wa, float(t)) for t in ts])
            ax.fill_between(ts, wa, up, color="tab:green", alpha=0.3, label="stable (eq. 27)")
            ax.plot(ts, up, color="tab:green", lw=1)
            ax.axhline(wa, color="k", lw=1)
            ax.set_title(f"Region of stability, w_A = {wa:g} rad/s (seed 001 Fig. 4)")
            ax.set_ylim(0, 1.3 * float(np.nanmax(up)))
        for n in (1, 2):
            ax.axvline(n * math.pi / wa, color="0.6", ls=":", lw=0.8)
        ax.set_xlabel("delay T (s)")
        if args.figure == 3:
            ax.set_ylim(0, 8 * wa)
        ax.set_ylabel("w_R (rad/s)")
    else:
        was = np.linspace(0.05, 2 * math.pi / args.delay * 0.999, 600)
        up = td.upper_bound_curve(was, args.delay)
        ax.fill_between(was, was, up, color="tab:green", alpha=0.3, label="stable: w_A <= w_R <= bound")
        ax.plot(was, up, color="tab:green", lw=1, label="upper bound of w_R (eq. 27)")
        ax.plot(was, was, color="k", lw=1, label="w_R = w_A")
        ax.axhline(args.omega_r, color="tab:red", ls="--", lw=1, label=f"w_R = {args.omega_r:g} rad/s")
        ax.set_xlabel("assumed frequency w_A (rad/s)")
        ax.set_ylabel("w_R (rad/s)")
        ax.set_ylim(0, 3 * args.omega_r + 5)
        ax.set_title(f"Stability region for T = {args.delay:g} s (seed 001 Fig. 6)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, args.out)
    return json.dumps({"out": args.out}) if args.json else f"wrote {args.out}"


def _upper(wa: float, t: float) -> float:
    try:
        return td.stable_interval(wa, t).upper
    except td.TimeDelayError:
        return float("nan")


# ------------------------------------------------------------------------------------------------ seed 002


def _failing_bands(design: str, delta: float, gain: float | None) -> list[list[float]]:
    """Frequency bands (rad/s) of a dense grid over 1..1e4 rad/s where some plant of the box fails."""
    w = np.logspace(0, 4, 1200)
    bad = qft.worst_case(design, w, gain=gain) > delta
    bands, start = [], None
    for i, b in enumerate(bad):
        if b and start is None:
            start = w[i]
        if not b and start is not None:
            bands.append([float(start), float(w[i - 1])])
            start = None
    if start is not None:
        bands.append([float(start), float(w[-1])])
    return bands


def _cmd_qft_table(args: argparse.Namespace) -> str:
    rows = qft.matching_table(args.design, args.frequencies, [*qft.corners(), qft.nominal()], args.delta, args.gain)
    gain = None if args.design == "open" else (args.gain or qft.design_gain(args.design))
    specs = {}
    for name in ("output_disturbance", "input_disturbance", "noise"):
        specs[name] = np.max([qft.loop_specs(args.design, p, args.frequencies, args.gain)[name]
                              for p in qft.plant_grid(5)], axis=0).tolist()
    marg = [] if args.design == "open" else qft.margins(args.design, gain=args.gain)
    failing = sorted({w for r in rows for w in r.violations})
    bands = _failing_bands(args.design, args.delta, args.gain)
    doc: dict[str, Any] = {
        "design": args.design, "gain": gain, "delta_m": args.delta, "frequencies": list(args.frequencies),
        "plants": [{"m": r.plant.m, "c": r.plant.c, "k": r.plant.k, "errors": list(r.errors),
                    "violations": list(r.violations)} for r in rows],
        "failing_frequencies": failing, "dense_grid_failing_bands": bands, "worst_case_specs": specs,
        "margins": [{"m": x.plant.m, "c": x.plant.c, "k": x.plant.k, "gain_margin": x.gain_margin,
                     "phase_margin_deg": x.phase_margin, "crossover": x.crossover, "stable": x.stable} for x in marg]}
    if args.json:
        return json.dumps(doc, indent=2)
    label = {"ffb": "feedforward-feedback (Fig. 4, spec 9)", "fb": "feedback (Fig. 2, spec 7)",
             "open": "open loop (Fig. 1)"}[args.design]
    head = [f"{label}" + (f", G of eq. (10) with gain {gain:g}" if gain else "") + f", F = P0, Gr = 1;"
            f" |M - Y/R| with M = P0, delta_m = {args.delta:g} ('*' = above delta_m)", ""]
    table = text_table(["plant (m kg, c N s/m, k N/m)"] + [f"{w:g}" for w in args.frequencies],
                   [[("nominal " if r.plant == qft.nominal() else "") + r.plant.label()]
                    + [f"{e:.4f}{'*' if e > args.delta else ' '}" for e in r.errors] for r in rows],
                   right=[False] + [True] * len(args.frequencies))
    out = [*head, table, ""]
    if failing:
        out.append("FAILS at " + ", ".join(f"{w:g}" for w in failing) + " rad/s: " + "; ".join(
            f"{w:g} rad/s by " + ", ".join(r.plant.label() for r in rows if w in r.violations) for w in failing))
    else:
        out.append(f"meets |M - Y/R| <= {args.delta:g} for every corner plant at every working frequency")
    out.append("dense grid 1..1e4 rad/s over the parameter box: " + (
        "fails in " + ", ".join(f"{a:.4g}-{b:.4g}" for a, b in bands) + " rad/s" if bands else "meets everywhere"))
    out += ["", "worst case over the parameter box (section 3.2):",
            text_table(["spec"] + [f"{w:g}" for w in args.frequencies],
                   [[n] + [f"{v:.4g}" for v in vals] for n, vals in specs.items()],
                   right=[False] + [True] * len(args.frequencies))]
    if marg:
        worst = min(marg, key=lambda x: x.phase_margin)
        stability = "all stable" if all(x.stable for x in marg) else "UNSTABLE for some"
        out += ["", f"loop L = P G on the corners: {stability};"
                f" crossover {min(x.crossover for x in marg):.4g}-{max(x.crossover for x in marg):.4g} rad/s;"
                f" smallest phase margin {worst.phase_margin:.3g} deg ({worst.plant.label()}),"
                f" smallest gain margin {min(x.gain_margin for x in marg):.3g}"]
    return "\n".join(out)


def _cmd_qft_plot(args: argparse.Namespace) -> str:
    plt = _plt()
    w = np.logspace(0, 4, 800)
    if args.figure == 6:
        fig, axes = plt.subplots(1, 3, figsize=(15, 5), dpi=100, sharey=True)
        phases = np.linspace(-359.0, 0.0, 360)
        p0 = qft.plant_tf(qft.nominal())
        shapes = [("unshaped L0 = P0 (G = 1), spec (7)", "fb", None),
                  (f"feedback, G gain {qft.GAIN_FB:g}, spec (7)", "fb", qft.GAIN_FB),
                  (f"feedforward-feedback, G gain {qft.GAIN_FFB:g}, spec (9)", "ffb", qft.GAIN_FFB)]
        colors = plt.cm.viridis(np.linspace(0, 0.9, len(qft.WORKING_FREQUENCIES)))
        for ax, (title, spec, gain) in zip(axes, shapes, strict=True):
            l0 = p0 if gain is None else qft.controller_tf(gain) * p0
            ph, mag = qft.nichols(l0(1j * w))
            ax.plot(np.unwrap(np.radians(ph)) * 180 / math.pi, mag, "k", lw=1.2, label="L0")
            for col, om in zip(colors, qft.WORKING_FREQUENCIES, strict=True):
                _, up = qft.bounds(spec, om, phases)
                ax.plot(phases, up, color=col, lw=1, label=f"{om:g} rad/s")
                tph, tmag = qft.nichols(qft.template(om, qft.plant_grid(5)) * (l0(1j * om) / p0(1j * om)))
                ax.plot(tph, tmag, ".", color=col, ms=1.5)
                lph, lmag = qft.nichols(np.array([l0(1j * om)]))
                ax.plot(lph, lmag, "o", color=col, mec="k")
            ax.set_title(title, fontsize=9)
            ax.set_xlabel("open-loop phase (deg)")
            ax.set_xlim(-360, 0)
            ax.set_ylim(-40, 80)
            ax.grid(alpha=0.3)
        axes[0].set_ylabel("open-loop magnitude (dB)")
        axes[0].legend(fontsize=7)
        fig.suptitle("Seed 002 Fig. 6: bounds (lines), templates (dots) and L0 (circles at the working frequencies)")
    elif args.figure == 7:
        fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=110)
        for gain, style, name in ((qft.GAIN_FB, "-", "feedback"), (qft.GAIN_FFB, "--", "feedforward-feedback")):
            ax.semilogx(w, 20 * np.log10(np.abs(qft.controller_tf(gain)(1j * w))), style,
                        label=f"{name} (K = {gain:g})")
        ax.set_xlabel("frequency (rad/s)")
        ax.set_ylabel("|G| (dB)")
        ax.set_title("Seed 002 Fig. 7: controller magnitudes")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    else:
        fig, (top, bot) = plt.subplots(2, 1, figsize=(7.5, 7), dpi=110, sharex=True)
        p0 = np.abs(qft.plant_tf(qft.nominal())(1j * w))
        for p in qft.corners():
            top.semilogx(w, 20 * np.log10(np.abs(qft.closed_loop("ffb", p)(1j * w))), lw=0.8)
            bot.semilogx(w, 20 * np.log10(np.abs(qft.plant_tf(p)(1j * w))), lw=0.8)
        for ax, title in ((top, "Y/R, feedforward-feedback, eight corner plants"), (bot, "plant P, eight corners")):
            ax.semilogx(w, 20 * np.log10(p0), "k--", lw=1.5, label="M = P0")
            ax.set_ylabel("magnitude (dB)")
            ax.set_title(title, fontsize=9)
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=8)
            ax.set_ylim(-60, 20)
        bot.set_xlabel("frequency (rad/s)")
        fig.suptitle("Seed 002 Fig. 8")
    fig.tight_layout()
    _save(fig, args.out)
    return json.dumps({"out": args.out}) if args.json else f"wrote {args.out}"


COMMANDS = {"tdf-interval": _cmd_tdf_interval, "tdf-step": _cmd_tdf_step, "tdf-select": _cmd_tdf_select,
            "tdf-plot": _cmd_tdf_plot, "qft-table": _cmd_qft_table, "qft-plot": _cmd_qft_plot}


@survives_closed_pipe
def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (0 ok, 2 bad input)."""
    return run(PROG, build_parser(), COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
