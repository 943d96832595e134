"""``python -m sim_plant_node.demo``: the demo (``./run demo``), which lives in :mod:`.clients.demo`."""

from .clients.demo import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
