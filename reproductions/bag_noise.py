"""Bag analysis with measured joint states: noise and encoder steps against moves found and mode.

``python -m reproductions.bag_noise`` (``./run exec python -m reproductions.bag_noise``) writes
robot-style recordings (:func:`shaper_nodes.analysis.synthetic.check_segmentation`: six
back-and-forth moves of 0.5 rad at 500 Hz, a 4 Hz mode with damping 0.02, IMU with gravity and
0.01 m/s^2 noise, joint states with the given noise and steps, no commands and no cycle events),
analyses them as ``analyze_bag`` does, and rewrites the table between the ``noise-table`` markers
of docs/results/bag_analysis_figures.md. The unit test ``test_noisy_joint_states_are_segmented`` checks the same
figures.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import tempfile

from reproductions.common import docs_option

#: (joint-state noise in rad, encoder step in rad) of the table
CASES: tuple[tuple[float, float], ...] = (
    (0.0, 0.0), (1e-5, 0.0), (3e-5, 0.0), (1e-4, 0.0),
    (0.0, 2 * math.pi / 2**20), (1e-5, 2 * math.pi / 2**16),
)
BEGIN, END = "<!-- noise-table begin -->", "<!-- noise-table end -->"


def table(folder: pathlib.Path) -> str:
    """The Markdown table of :data:`CASES`, recordings written into ``folder``."""
    from shaper_nodes.analysis.synthetic import check_segmentation

    lines = ["| joint noise (rad) | encoder step (rad) | moves found / true | start error (ms) | end error (ms) |"
             " mode (Hz), true 4 | mode error | recommended |", "|---|---|---|---|---|---|---|---|"]
    for noise, step in CASES:
        c = check_segmentation(folder, noise, step)
        lines.append(f"| {noise:g} | {step:.3g} | {c.moves_found} / {c.moves_true} | {1e3 * c.start_error:.0f} |"
                     f" {1e3 * c.end_error:.0f} | {c.mode_hz:.5f} | {100 * c.mode_error:.2g} % | {c.recommended} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bag_noise", description=__doc__.split("\n\n")[0])
    docs_option(p, "bag_analysis_figures.md (its noise table)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        text = table(pathlib.Path(tmp))
    doc = args.docs / "bag_analysis_figures.md"
    src = doc.read_text()
    if BEGIN not in src or END not in src:
        raise SystemExit(f"{doc}: no {BEGIN} ... {END} markers to put the table between")
    head, rest = src.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    doc.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
