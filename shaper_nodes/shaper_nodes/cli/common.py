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
