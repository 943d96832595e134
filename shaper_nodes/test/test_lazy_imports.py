"""The nodes start without the heavy modules they do not need yet (issue 34: the suite's CPU).

Each started process pays for its imports: scipy.signal and scipy.stats were 0.6 s of CPU, scipy.optimize and
scipy.interpolate 0.3 s, Pinocchio 0.1 s, at every start of a node, a CLI or its ``--help``
(docs/results/testing.md, "Where the CPU goes"). They are imported where they are used, except where the first use
is inside a callback that someone waits for (the identification's numerics in the identifier's ``~/identify``; the
LIST learner's filter at a cycle's END): those stay at the start. This checks, in a fresh interpreter, that
importing the executables' modules (what ``--help`` and a node's start do before the node is made) loads none of
them, so a module-level import added later is caught here.
"""

from __future__ import annotations

import json
import subprocess
import sys

#: modules these executables' start must not load (imported where they are used)
HEAVY = ("scipy.optimize", "scipy.signal", "scipy.stats", "scipy.interpolate", "scipy.special", "scipy.linalg",
         "control", "matplotlib", "dask", "pinocchio")

#: the modules of the executables that need none of them at start, and the conductor the reproductions start
#: nodes with (identifier, list_replay, analyze_bag and analyze_fleet identify modes: they import the
#: identification's numerics at start; calibrate identifies in its workers, or after its last pose)
MODULES = ["shaper_nodes.nodes.shaper", "shaper_nodes.nodes.recorder", "shaper_nodes.nodes.learner",
           "shaper_nodes.nodes.calibrate",
           "shaper_nodes.nodes.scheduler", "shaper_nodes.nodes.bag_play", "shaper_nodes.cli.shaper_design",
           "shaper_nodes.cli.loop_design", "shaper_nodes.cli.keystore", "shaper_nodes.cli.send_goal",
           "sim_plant_node.node.sim_plant", "sim_plant_node.clients.demo", "sim_plant_node.clients.conductor"]

#: imports the modules one after the other in one interpreter (one start's CPU for the whole check), and says which
#: heavy modules each one added
PROBE = """import importlib, json, sys
heavy = json.loads(sys.argv[1])
added = {}
for module in sys.argv[2:]:
    importlib.import_module(module)
    added[module] = [m for m in heavy if m in sys.modules and not any(m in v for v in added.values())]
print(json.dumps(added))
"""


def test_no_executables_module_loads_a_heavy_module():
    out = subprocess.run([sys.executable, "-c", PROBE, json.dumps(HEAVY), *MODULES], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    added = {module: heavy for module, heavy in json.loads(out.stdout).items() if heavy}
    assert added == {}, f"imported at start: {added}"


def test_the_lazy_imports_still_import_when_used():
    """The functions that use them work (the same functions run; the core's own tests check their numbers)."""
    from shaper_nodes.core.shaping import design
    from shaper_nodes.core.shaping.types import Mode
    from shaper_nodes.core.shaping.vibration import insensitivity_width

    for family in ("zvd", "ei"):  # scipy.special's comb; scipy.optimize's root finding in the band's edges
        shaper = design(family, [Mode(12.0, 0.05)])
        assert abs(float(sum(shaper.amplitudes)) - 1.0) < 1e-12
        assert insensitivity_width(shaper.amplitudes, shaper.times, 12.0, 0.05) > 0.0


def test_the_filters_need_no_scipy():
    """The stream's filters run on numpy alone (the block path's taps are two numpy passes since session 9: BLAS
    daxpy made an output's last bit depend on the block boundaries on CPUs that fuse in its vector body), so a
    shaper node's start and its first block load no scipy.linalg."""
    probe = ("import sys\n"
             "import numpy as np\n"
             "from shaper_nodes.core.shaping import StreamingShaper, design, discretize\n"
             "fir = discretize(design('none'), 500.0)\n"
             "StreamingShaper(fir, 3).process(np.zeros((700, 3)))\n"
             "print('scipy.linalg' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False"]
