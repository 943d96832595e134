"""What the command-line tools share: argument types, the parser that does not exit, text tables
and the ``main`` that turns errors into exit status 2.

Every CLI prints its result on stdout and exits 0; bad input prints one line naming the problem
on stderr (``PROG: error: ...``) and exits 2; ``--help`` exits 0. A reader that closes the pipe
early (``shaper_design list | head -1``) ends the CLI quietly with status 141, as a shell reports
a process ended by SIGPIPE (:func:`shaper_nodes.core.closed_pipe.survives_closed_pipe`).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NoReturn


class UsageError(Exception):
    """Bad command-line input; the message names the problem (exit status 2)."""


def number(what: str, positive: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite float (and > 0 if ``positive``), else an error naming ``what``."""

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what} must be a number, got {text!r}") from None
        if not (math.isfinite(x) and (x > 0.0 or not positive)):
            raise argparse.ArgumentTypeError(f"{what} must be finite{' and > 0' if positive else ''}, got {text!r}")
        return x

    return parse


class Parser(argparse.ArgumentParser):
    """ArgumentParser that raises UsageError instead of exiting, so ``main`` returns the status."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}")


def is_number(text: str) -> bool:
    """Whether ``text`` reads as a float."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def text_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], right: Sequence[bool] | None = None) -> str:
    """Aligned text table; columns of numbers right-aligned unless ``right`` says otherwise."""
    cells = [[str(c) for c in row] for row in rows]
    widths = [max([len(h)] + [len(r[i]) for r in cells]) for i, h in enumerate(headers)]
    if right is None:
        right = [all(is_number(r[i]) for r in cells) for i in range(len(headers))]
    align = right

    def line(items: Sequence[str]) -> str:
        return "  ".join(s.rjust(w) if r else s.ljust(w) for s, w, r in zip(items, widths, align, strict=True)).rstrip()

    return "\n".join([line(headers), line(["-" * w for w in widths]), *(line(r) for r in cells)])


def run(prog: str, parser: argparse.ArgumentParser, commands: Mapping[str, Callable[[argparse.Namespace], str]],
        argv: Sequence[str] | None) -> int:
    """Parse ``argv``, run the chosen command and print its text; returns the exit status (0 ok,
    2 bad input: a UsageError or a ValueError from the core, printed as ``prog: error: ...``)."""
    try:
        args = parser.parse_args(argv)
        text = commands[args.command](args)
    except UsageError as exc:
        msg = str(exc)
        print(msg if msg.startswith(prog) else f"{prog}: error: {msg}", file=sys.stderr)
        return 2
    except ValueError as exc:  # the core's errors (ShaperError, TimeDelayError, QftError, ...) name the problem
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    print(text)
    return 0


# ------------------------------------------------------------------------------ analysis options
def band_hz(text: str) -> tuple[float, float]:
    """An argparse type: ``LOW,HIGH`` in Hz, 0 <= LOW < HIGH."""
    try:
        lo, hi = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH in Hz, got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise argparse.ArgumentTypeError(f"expected 0 <= LOW < HIGH in Hz, got {text!r}")
    return lo, hi


def count(what: str) -> Callable[[str], int]:
    """An argparse type: an integer >= 0, else an error naming ``what``."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what} must be an integer, got {text!r}") from None
        if n < 0:
            raise argparse.ArgumentTypeError(f"{what} must be >= 0, got {text!r}")
        return n

    return parse


def add_analysis_options(p: argparse._ActionsContainer) -> None:
    """The options of the analysis of one recording (:class:`~shaper_nodes.analysis.analyze.Options`),
    one copy for ``analyze_bag`` and ``analyze_fleet``; defaults are the Options dataclass's."""
    from shaper_nodes.analysis.analyze import (
        BAND_SIGMAS,
        DEFAULT_SETTLE_TOLERANCE,
        SETTLE_SIGMAS,
        Options,
    )

    d = Options()
    p.add_argument("--segmentation", choices=("auto", "events", "motion"), default=d.segmentation,
                   help="cycles from the cycle events, or from the motion of the commands (auto: events if any)")
    p.add_argument("--positions", choices=("auto", "joints", "commands"), default=d.positions,
                   help="positions whose rest starts the residual window (auto: joint states, else commands)")
    p.add_argument("--settle-tolerance", type=number("--settle-tolerance", positive=True), default=None,
                   metavar="TOL",
                   help="positions within this of their final value are at rest, rad or m. Default: from the"
                        f" recording: {DEFAULT_SETTLE_TOLERANCE:g} raised to {SETTLE_SIGMAS:g} x the noise measured"
                        " in the positions (or 2 encoder steps), and a joint that has reached or crossed its"
                        " final value after the move is at rest too (measured joint states ring about it when an"
                        " elastic structure pulls on the motors). Given: only the tolerance rule")
    p.add_argument("--band", default=d.band, help="settling band: m/s^2, or a percentage of the cycle's peak"
                   f" (default {d.band.replace('%', '%%')}); at least {BAND_SIGMAS:g} x the accelerometer noise"
                   " measured")
    p.add_argument("--remove-mean", choices=("auto", "yes", "no"), default=d.remove_mean,
                   help="remove each window's mean acceleration (gravity, bias); auto: when the recording"
                        " has a clear offset")
    p.add_argument("--method", default=d.method, help="identification method: fit, spectral, matrix_pencil")
    p.add_argument("--max-modes", type=count("--max-modes"), default=d.max_modes,
                   help="most modes to identify per cycle (default %(default)s)")
    p.add_argument("--band-hz", type=band_hz, help="look for modes in LOW,HIGH Hz only")
    p.add_argument("--identify-cycles", type=count("--identify-cycles"), default=d.identify_cycles,
                   help="identify the modes in at most this many cycles, evenly spread (0 = all; default %(default)s)")
    p.add_argument("--target", type=number("--target", positive=True), default=d.target,
                   help="largest acceptable worst-case percentage vibration, fraction (default %(default)s)")
    p.add_argument("--sigmas", type=number("--sigmas", positive=True), default=d.sigmas,
                   help="uncertainty box half-width, standard deviations (default %(default)s)")
    p.add_argument("--min-saving", type=number("--min-saving"), default=d.min_saving,
                   help="another shaper replaces the zero-residual default only if it is at least this fraction"
                        " shorter, 0..1 (default %(default)s)")
    p.add_argument("--max-damping", type=number("--max-damping", positive=True), default=d.max_damping,
                   help="modes damped above this ratio do not ring (a free decay falls to 14 %% in one period"
                        " at 0.3): reported but not used for the shaper (default %(default)g)")
    p.add_argument("--noise-sigmas", type=number("--noise-sigmas"), default=d.noise_sigmas,
                   help="modes whose initial amplitude is at most this many accelerometer noise standard"
                        " deviations (per axis, measured) are at the noise floor: reported but not used for the"
                        " shaper (default %(default)g)")
    p.add_argument("--motion-threshold", type=number("--motion-threshold", positive=True), metavar="SPEED",
                   help="cycles from the motion: a sample moves above this speed, rad/s or m/s (default: the"
                        " larger of 1 %% of the top speed and 6 x the speed noise measured in the positions)")


def analysis_options(args: argparse.Namespace, **extra: Any) -> Any:
    """The :class:`~shaper_nodes.analysis.analyze.Options` that :func:`add_analysis_options`' values ask
    for, with ``extra`` fields (e.g. learners)."""
    from shaper_nodes.analysis.analyze import Options

    return Options(settle_tolerance=args.settle_tolerance, band=args.band, remove_mean=args.remove_mean,
                   segmentation=args.segmentation, positions=args.positions, method=args.method,
                   max_modes=args.max_modes, band_hz=args.band_hz, identify_cycles=args.identify_cycles,
                   target=args.target, sigmas=args.sigmas, min_saving=args.min_saving,
                   max_damping=args.max_damping, noise_sigmas=args.noise_sigmas,
                   motion_threshold=args.motion_threshold, **extra)
