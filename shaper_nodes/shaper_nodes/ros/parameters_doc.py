"""The parameter reference (``docs/reference/parameters.md``) rendered from the nodes' tables.

:func:`render` turns sections (an executable, its tables of :class:`~.parameters.Spec`) into
Markdown: per parameter its name, type, default, range or choices, read-only, and description
with units. The command that collects the tables of every executable and writes (or checks) the
file is ``scripts/parameters_doc.py`` (it imports the nodes of both packages, so it sits above them).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from .node_main import yaml_value
from .parameters import TYPE_NAMES, Spec

#: the command that regenerates the reference (named by the test that fails when it is stale)
COMMAND = "./run exec python scripts/parameters_doc.py"

HEADER = f"""# Parameters (reference)

Generated from the nodes' parameter declarations by `{COMMAND}`; do not edit by hand
(`--check` fails when this file differs from the declarations; CI runs it as a test).
Every parameter has a value after start-up (`ros2 param dump` lists them all); an array
without a default is empty, read as "not set". A double takes an integer (`5` is `5.0`), a
double array an integer array, an array parameter an empty array of any type. Read-only
parameters are set at start-up only (params file, `-p`); a params file keyed `/**:` applies
whatever the node is named.
"""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _default(spec: Spec) -> str:
    return "`[]` (not set)" if spec.default is None else f"`{yaml_value(spec.default)}`"


def _bounds(spec: Spec) -> str:
    if spec.choices:
        return ", ".join(f"`{c}`" for c in spec.choices)
    if spec.range is None:
        return ""
    lo, hi = spec.range
    return f"{lo:g} to {hi:g}" if not spec.integer else f"{int(lo)} to {int(hi)}"


def render_table(specs: Iterable[Spec]) -> list[str]:
    """One Markdown table of ``specs``."""
    lines = ["| name | type | default | range / choices | read-only | description (units) |",
             "|---|---|---|---|---|---|"]
    for s in specs:
        lines.append(f"| `{s.name}` | {TYPE_NAMES[s.param_type]} | {_cell(_default(s))} | {_cell(_bounds(s))} | "
                     f"{'yes' if s.read_only else 'no'} | {_cell(s.description)} |")
    return lines


def render(sections: Sequence[tuple[str, str, Sequence[tuple[str, Iterable[Spec]]]]]) -> str:
    """The reference: ``sections`` is (executable, what it is, [(table heading, specs)...]) each."""
    out = [HEADER]
    out.append("Executables: " + ", ".join(f"[`{name}`](#{name})" for name, _, _ in sections)
               + ".\n")
    for name, what, tables in sections:
        out.append(f"## {name}\n")
        out.append(what + "\n")
        for heading, specs in tables:
            if heading:
                out.append(f"### {heading}\n")
            out.extend(render_table(specs))
            out.append("")
    return "\n".join(out).rstrip("\n") + "\n"


__all__ = ["COMMAND", "render", "render_table"]
