"""Cost of discretising a shaper to the command grid: ``exact`` against ``split`` and the design.

Timing (ROS-free, best of ``repeats`` passes of ``number`` calls each), per case (family, modes,
command rate):

``design``
    ``core.shaping.families.design``: what any shaper change costs already (the baseline).
``split``
    ``core.shaping.fir.discretize(..., "split")``.
``exact``
    ``core.shaping.fir.discretize(..., "exact")``: the split plus the least-change solve at the modes
    (and, when the split's taps would go negative, the bounded QP).

Both are paid once per shaper change, never per sample: the streaming cost is the FIR's (see
``fir_throughput``), and the exact FIR has the split's taps (one or two more with the QP).
Run it with ``python -m benchmarks.discretization`` or as part of ``python -m benchmarks``.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable

from shaper_nodes.core.shaping import Mode, design, discretize

from .scheduler import best_call_time as _best

#: (label, family, modes, command rate Hz)
CASES = (
    ("ZV 12 Hz at 1 kHz", "zv", (Mode.from_hz(12.0, 0.05),), 1000.0),
    ("ZVD 12 Hz at 250 Hz", "zvd", (Mode.from_hz(12.0, 0.05),), 250.0),
    ("ZVD 5 Hz undamped at 125 Hz (QP)", "zvd", (Mode.from_hz(5.0, 0.0),), 125.0),
    ("ZVD 4 + 11 Hz at 250 Hz", "zvd", (Mode.from_hz(4.0, 0.02), Mode.from_hz(11.0, 0.05)), 250.0),
    ("EI 8 Hz at 500 Hz", "ei", (Mode.from_hz(8.0, 0.03),), 500.0),
)


def run(number: int = 50, repeats: int = 5, progress: Callable[[str], None] | None = None) -> list[dict]:
    rows = []
    for label, family, modes, rate in CASES:
        if progress:
            progress(f"discretisation: {label}")
        shaper = design(family, modes)
        t_design = _best(functools.partial(design, family, modes), number, repeats)
        t_split = _best(functools.partial(discretize, shaper, rate, "split"), number, repeats)
        t_exact = _best(functools.partial(discretize, shaper, rate, "exact"), number, repeats)
        taps = (discretize(shaper, rate, "split").delays.size, discretize(shaper, rate, "exact").delays.size)
        rows.append({"case": label, "design_us": 1e6 * t_design, "split_us": 1e6 * t_split,
                     "exact_us": 1e6 * t_exact, "exact_over_split": t_exact / t_split,
                     "exact_over_design": t_exact / t_design, "taps_split": taps[0], "taps_exact": taps[1]})
    return rows


def print_table(rows: list[dict]) -> None:
    print("shaper discretisation, once per shaper change (best of 5 x 50 calls)")
    print(f"  {'case':34s} {'design us':>10s} {'split us':>9s} {'exact us':>9s} {'exact/split':>12s}"
          f" {'exact/design':>13s} {'taps':>7s}")
    for r in rows:
        print(f"  {r['case']:34s} {r['design_us']:10.1f} {r['split_us']:9.1f} {r['exact_us']:9.1f}"
              f" {r['exact_over_split']:12.1f} {r['exact_over_design']:13.2f}"
              f" {r['taps_split']:>3d}/{r['taps_exact']:<3d}")


def main() -> int:
    print_table(run(progress=lambda s: print(f"[bench] {s}", file=sys.stderr, flush=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
