"""``shaper_design``: list, inspect, compare and plot the shaper families from the command line.

Subcommands (``shaper_design SUBCOMMAND --help`` for the options)::

    shaper_design list
    shaper_design show FAMILY --frequency HZ [--frequency HZ ...] --damping Z [--rate HZ]
    shaper_design compare --frequency HZ --damping Z [--families F ...]
    shaper_design plot --frequency HZ --damping Z [--families F ...] --out FILE.png

Frequencies are natural frequencies in Hz, damping ratios dimensionless; V is printed in %.
Tables are aligned text by default; ``--json`` prints one JSON document instead. Bad input
prints a message naming the problem on stderr and exits with status 2. Also runs as
``ros2 run shaper_nodes shaper_design``; it needs no ROS.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from shaper_nodes.core.closed_pipe import survives_closed_pipe
from shaper_nodes.core.shaping import (
    DEFAULT_INSENSITIVITY,
    DEFAULT_VIBRATION_TOLERANCE,
    FAMILIES,
    Mode,
    Shaper,
    ShaperError,
    design,
    discretize,
    family_info,
    family_params,
    fir_impulses,
    insensitivity_width,
    percentage_vibration,
)

from .common import Parser, UsageError, number, run, text_table

#: families compared and plotted when --families is not given
DEFAULT_FAMILIES = ("zv", "zvd", "zvdd", "mzv", "ei", "2hump_ei", "3hump_ei", "si")
#: level of the insensitivity column and of the plot's reference line, fraction
LEVEL = 0.05

PROG = "shaper_design"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = Parser(prog=PROG, description="Design and compare input shapers (no ROS needed).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    def common(p: argparse.ArgumentParser, repeat_frequency: bool) -> None:
        action = "append" if repeat_frequency else "store"
        p.add_argument("--frequency", "-f", type=number("--frequency (Hz)", positive=True), required=True,
                       action=action,
                       help="natural frequency of the mode, Hz" + (" (repeat for several modes)" * repeat_frequency))
        p.add_argument("--damping", "-z", type=number("--damping"), required=True, action=action,
                       help="damping ratio, in [0, 0.95]"
                       + (" (one for all, or one per --frequency)" * repeat_frequency))
        p.add_argument("--tolerance", type=number("--tolerance"), default=DEFAULT_VIBRATION_TOLERANCE,
                       help="vibration tolerance V_tol of ei, 2hump_ei, 3hump_ei, si, fraction (default %(default)s)")
        p.add_argument("--insensitivity", type=number("--insensitivity"), default=DEFAULT_INSENSITIVITY,
                       help="si band width / design frequency (default %(default)s)")
        p.add_argument("--derivative-order", type=int, default=1, help="n of zvdn (default %(default)s)")
        p.add_argument("--json", action="store_true", help="print one JSON document")

    p_list = sub.add_parser("list", help="the families: description, impulses, damping assumed")
    p_list.add_argument("--json", action="store_true", help="print one JSON document")

    p_show = sub.add_parser("show", help="impulses, duration, V and insensitivity of one design")
    p_show.add_argument("family", help="family name (see 'list')")
    common(p_show, repeat_frequency=True)
    p_show.add_argument("--amplitudes", type=number("--amplitudes"), nargs="+", help="custom family: amplitudes")
    p_show.add_argument("--times", type=number("--times"), nargs="+", help="custom family: impulse times, s")
    p_show.add_argument("--rate", type=number("--rate (Hz)", positive=True),
                        help="command rate, Hz: also show the discretised FIR")
    p_show.add_argument("--discretization", choices=("split", "round", "exact"), default="split",
                        help="impulse times between samples (default %(default)s)")

    p_cmp = sub.add_parser("compare", help="table of families at one mode")
    common(p_cmp, repeat_frequency=False)
    p_cmp.add_argument("--families", nargs="+", default=list(DEFAULT_FAMILIES), help="families to compare")

    p_plot = sub.add_parser("plot", help="sensitivity curves (V %% against frequency) to a PNG")
    common(p_plot, repeat_frequency=False)
    p_plot.add_argument("--families", nargs="+", default=list(DEFAULT_FAMILIES), help="families to plot")
    p_plot.add_argument("--out", required=True, help="output image file (.png)")
    p_plot.add_argument("--max-ratio", type=number("--max-ratio", positive=True), default=2.0,
                        help="plot up to this multiple of the frequency (default %(default)s)")
    return parser


# ------------------------------------------------------------------------------------------------


def _modes(frequencies: Sequence[float], dampings: Sequence[float]) -> list[Mode]:
    if len(dampings) not in (1, len(frequencies)):
        raise UsageError(f"give one --damping for all modes or one per --frequency"
                         f" ({len(frequencies)} frequencies, {len(dampings)} dampings)")
    zetas = list(dampings) * len(frequencies) if len(dampings) == 1 else list(dampings)
    return [Mode.from_hz(f, z) for f, z in zip(frequencies, zetas, strict=True)]


def _family(name: str) -> str:
    key = name.strip().lower()
    if key not in FAMILIES:
        raise UsageError(f"unknown shaper family {name!r}; known: {', '.join(FAMILIES)}")
    return key


def _design(family: str, modes: Sequence[Mode], args: argparse.Namespace, **extra: Any) -> Shaper:
    return design(family, modes, derivative_order=args.derivative_order, vibration_tolerance=args.tolerance,
                  insensitivity=args.insensitivity, **extra)


def _v(shaper: Shaper | tuple[np.ndarray, np.ndarray], mode: Mode) -> float:
    amps, times = (shaper.amplitudes, shaper.times) if isinstance(shaper, Shaper) else shaper
    return float(percentage_vibration(amps, times, mode.omega, mode.zeta))


def _pct(x: float) -> str:
    return f"{100.0 * x:.3g}"


def _params(shaper: Shaper) -> dict[str, float]:
    return {k: (int(v) if k == "derivative_order" else float(v)) for k, v in shaper.params.items()}


# ------------------------------------------------------------------------------------------------


def _cmd_list(args: argparse.Namespace) -> str:
    infos = {name: family_info(name) for name in FAMILIES}
    if args.json:
        return json.dumps({"families": [
            {"family": n, "description": i.description, "impulses": i.impulses, "damping_assumed": i.damping,
             "parameters": list(i.params), "modes": "joint" if i.joint else "convolution"}
            for n, i in infos.items()]}, indent=2)
    rows = [(n, i.impulses, i.description) for n, i in infos.items()]
    out = [text_table(("family", "impulses", "description"), rows, right=(False, False, False)), "", "damping assumed:"]
    out += [f"  {n:9s} {i.damping}" for n, i in infos.items()]
    return "\n".join(out)


def _cmd_show(args: argparse.Namespace) -> str:
    family = _family(args.family)
    modes = _modes(args.frequency, args.damping)
    extra: dict[str, Any] = {}
    if family == "custom":
        if args.amplitudes is None or args.times is None:
            raise UsageError("family 'custom' needs --amplitudes and --times")
        extra = {"amplitudes": args.amplitudes, "times": args.times}
    shaper = _design(family, modes, args, **extra)
    per_mode = [{"frequency_hz": m.hz, "damping_ratio": m.zeta, "v_at_design": _v(shaper, m),
                 "insensitivity_5pct": insensitivity_width(shaper.amplitudes, shaper.times, m.omega, m.zeta, LEVEL)}
                for m in modes]
    doc: dict[str, Any] = {
        "family": shaper.family,
        "damping_assumed": family_info(shaper.family).damping,
        "params": _params(shaper),
        "impulses": [{"time_s": float(t), "amplitude": float(a)}
                     for a, t in zip(shaper.amplitudes, shaper.times, strict=True)],
        "duration_s": shaper.duration,
        "modes": per_mode,
    }
    fir = None
    if args.rate is not None:
        fir = discretize(shaper, args.rate, args.discretization)
        fa, ft = fir_impulses(fir, args.rate)
        doc["fir"] = {
            "rate_hz": args.rate, "discretization": args.discretization,
            "taps": [{"index": int(d), "time_s": float(d) / args.rate, "weight": float(g)}
                     for d, g in zip(fir.delays, fir.gains, strict=True)],
            "v_at_design": [_v((fa, ft), m) for m in modes],
        }
    if args.json:
        return json.dumps(doc, indent=2)
    params = ", ".join(f"{k}={v:g}" for k, v in doc["params"].items())
    out = [f"family {shaper.family}{f' ({params})' if params else ''}; {doc['damping_assumed']}", ""]
    out.append(text_table(("#", "time (s)", "amplitude"),
                      [(i, f"{t:.6f}", f"{a:.6f}")
                       for i, (a, t) in enumerate(zip(shaper.amplitudes, shaper.times, strict=True))]))
    out += ["", f"duration {shaper.duration:.6f} s", ""]
    out.append(text_table(("mode (Hz)", "damping", "V at mode (%)", f"{100 * LEVEL:g} % insensitivity"),
                      [(f"{m['frequency_hz']:g}", f"{m['damping_ratio']:g}", _pct(m["v_at_design"]),
                        f"{m['insensitivity_5pct']:.4f}") for m in per_mode]))
    if fir is not None:
        out += ["", f"FIR at {args.rate:g} Hz ({args.discretization}): {fir.length} taps,"
                f" {len(fir.delays)} non-zero", ""]
        out.append(text_table(("sample", "time (s)", "weight"),
                          [(t["index"], f"{t['time_s']:.6f}", f"{t['weight']:.6f}") for t in doc["fir"]["taps"]]))
        out += ["", "V of the FIR at each mode (%): " + ", ".join(_pct(v) for v in doc["fir"]["v_at_design"])]
    return "\n".join(out)


def _compare_rows(args: argparse.Namespace) -> tuple[Mode, list[dict[str, Any]]]:
    mode = Mode.from_hz(args.frequency, args.damping)
    families = [_family(f) for f in args.families]
    for fam in families:  # bad parameters are usage errors; a design that does not exist is a row
        if fam == "custom":
            raise UsageError("family 'custom' cannot be compared (it has no design); use 'show custom'")
        family_params(fam, derivative_order=args.derivative_order, vibration_tolerance=args.tolerance,
                      insensitivity=args.insensitivity)
    rows: list[dict[str, Any]] = []
    for fam in families:
        try:
            s = _design(fam, [mode], args)
        except ShaperError as exc:
            rows.append({"family": fam, "error": str(exc)})
            continue
        rows.append({
            "family": fam, "impulses": len(s), "duration_s": s.duration,
            "duration_periods": s.duration / mode.damped_period, "v_at_design": _v(s, mode),
            "insensitivity_5pct": insensitivity_width(s.amplitudes, s.times, mode.omega, mode.zeta, LEVEL),
            "shaper": s,
        })
    return mode, rows


def _cmd_compare(args: argparse.Namespace) -> str:
    mode, rows = _compare_rows(args)
    if args.json:
        return json.dumps({
            "frequency_hz": mode.hz, "damping_ratio": mode.zeta, "vibration_tolerance": args.tolerance,
            "insensitivity": args.insensitivity, "level": LEVEL,
            "families": [{k: v for k, v in r.items() if k != "shaper"} for r in rows]}, indent=2)
    table = text_table(
        ("family", "impulses", "duration (s)", "duration (T_d)", "V at mode (%)", f"{100 * LEVEL:g} % insensitivity"),
        [(r["family"], "-", "-", "-", "-", "not designed") if "error" in r else
         (r["family"], r["impulses"], f"{r['duration_s']:.5f}", f"{r['duration_periods']:.4f}",
          _pct(r["v_at_design"]), f"{r['insensitivity_5pct']:.4f}") for r in rows],
        right=(False, True, True, True, True, True))
    head = (f"mode {mode.hz:g} Hz, damping {mode.zeta:g} (T_d = {mode.damped_period:.5f} s);"
            f" V_tol {args.tolerance:g}, si insensitivity {args.insensitivity:g}")
    notes = [f"{r['family']}: {r['error']}" for r in rows if "error" in r]
    out = [head, "", table]
    if notes:
        out += ["", *notes]
    return "\n".join(out)


def _cmd_plot(args: argparse.Namespace) -> str:
    mode, rows = _compare_rows(args)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hz = np.linspace(0.0, args.max_ratio * mode.hz, 1201)
    fig, (full, zoom) = plt.subplots(2, 1, figsize=(9.5, 7.0), dpi=110, sharex=True,
                                     gridspec_kw={"height_ratios": (3, 2)})
    for r in rows:
        if "error" in r:
            continue
        s = r["shaper"]
        v = 100.0 * percentage_vibration(s.amplitudes, s.times, 2.0 * math.pi * hz, mode.zeta)
        label = f"{r['family']} ({r['duration_periods']:.2f} T_d)"
        full.plot(hz, v, label=label)
        zoom.plot(hz, v, label=label)
    for ax, top in ((full, 100.0), (zoom, 4.0 * 100.0 * LEVEL)):
        ax.axhline(100.0 * LEVEL, color="k", linestyle="--", linewidth=0.8, label=f"{100 * LEVEL:g} %")
        ax.axvline(mode.hz, color="0.6", linewidth=0.6)
        ax.set_ylim(0.0, top)
        ax.set_ylabel("residual vibration V (%)")
        ax.grid(True, alpha=0.3)
    zoom.set_xlabel("natural frequency of the plant (Hz); damping held at the design value")
    full.set_xlim(hz[0], hz[-1])
    full.set_title(f"Sensitivity curves: design mode {mode.hz:g} Hz, damping {mode.zeta:g}"
                   f" (lower panel: detail below {4 * 100 * LEVEL:g} %)")
    full.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="family (duration)")
    fig.tight_layout()
    try:
        fig.savefig(args.out)
    except (OSError, ValueError) as exc:
        raise UsageError(f"cannot write {args.out!r}: {exc}") from None
    finally:
        plt.close(fig)
    if args.json:
        return json.dumps({"out": args.out, "families": [r["family"] for r in rows if "error" not in r]})
    return f"wrote {args.out}"


COMMANDS = {"list": _cmd_list, "show": _cmd_show, "compare": _cmd_compare, "plot": _cmd_plot}


@survives_closed_pipe
def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (0 ok, 2 bad input)."""
    return run(PROG, build_parser(), COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
