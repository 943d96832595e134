"""Write (or check) docs/reference/parameters.md from the parameter declarations of every node.

Run: ``./run exec python scripts/parameters_doc.py`` to regenerate the file, ``--check`` to exit 1
(printing the first differing lines) when the file differs from the declarations. The rendering is
:mod:`shaper_nodes.ros.parameters_doc`; this script only collects the tables of the executables of
both packages (hence it sits above them, as the reproductions do).
"""

from __future__ import annotations

import argparse
import difflib
import pathlib
import sys
from collections.abc import Iterable, Sequence

from shaper_nodes.nodes import (
    bag_play,
    calibrate,
    identifier,
    learner,
    learner_list,
    learner_moves_mrilc,
    learner_mrilc,
    learner_payback,
    learner_speed_parameters,
    recorder,
    scheduler,
    shaper,
)
from shaper_nodes.ros.parameters import Spec
from shaper_nodes.ros.parameters_doc import render
from sim_plant_node.node import sim_plant

ROOT = pathlib.Path(__file__).resolve().parents[1]
TARGET = ROOT / "docs" / "reference" / "parameters.md"


def sections() -> list[tuple[str, str, Sequence[tuple[str, Iterable[Spec]]]]]:
    """Every executable that declares parameters: (name, what it is, its tables)."""
    return [
        ("shaper_node", "The shaper (`shaper_nodes.nodes.shaper`).", [("", shaper.PARAMETERS)]),
        ("identifier", "Mode identification (`shaper_nodes.nodes.identifier`).", [("", identifier.PARAMETERS)]),
        ("learner", "The learner (`shaper_nodes.nodes.learner`): the parameters of every mode, then those of the"
         " mode chosen by `mode`.", [("every mode", learner.PARAMETERS), ("mode list", learner_list.PARAMETERS),
                                    ("mode list with list.per_move", learner_payback.PARAMETERS),
                                    ("mode mrilc", learner_mrilc.PARAMETERS),
                                    ("mode mrilc_moves", learner_moves_mrilc.PARAMETERS),
                                    ("mode speed_moves", learner_speed_parameters.PARAMETERS)]),
        ("scheduler", "Gain scheduling (`shaper_nodes.nodes.scheduler`); each name of `rule_names` adds"
         " `rules.<name>.*` (below, with `<name>` for the rule).",
         [("", scheduler.PARAMETERS), ("each rule", scheduler.rule_table("<name>"))]),
        ("recorder", "The recorder (`shaper_nodes.nodes.recorder`).", [("", recorder.PARAMETERS)]),
        ("bag_play", "Playback of a recording (`shaper_nodes.nodes.bag_play`).", [("", bag_play.PARAMETERS)]),
        ("calibrate", "Calibration of an arm (`shaper_nodes.nodes.calibrate`).", [("", calibrate.PARAMETERS)]),
        ("sim_plant", "The simulated plant (`sim_plant_node.node.sim_plant`).", [("", sim_plant.PARAMETERS)]),
    ]


def generate() -> str:
    """The reference as the declarations give it."""
    return render(sections())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the file differs from the declarations")
    opts = parser.parse_args(argv)
    text = generate()
    if opts.check:
        have = TARGET.read_text(encoding="utf-8") if TARGET.exists() else ""
        if have == text:
            return 0
        diff = difflib.unified_diff(have.splitlines(), text.splitlines(), str(TARGET), "declarations", lineterm="")
        print("\n".join(list(diff)[:40]), file=sys.stderr)
        print(f"{TARGET.relative_to(ROOT)} is stale: run ./run exec python scripts/parameters_doc.py", file=sys.stderr)
        return 1
    TARGET.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
