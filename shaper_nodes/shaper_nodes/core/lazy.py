"""Modules imported on first use, so that a process that never needs them does not pay for them.

python-control pulls in scipy.signal, scipy.stats and matplotlib.pyplot: about 1 s of CPU at every
start of a process that imports it (a sim plant node, an executable's ``--help``), although most
of them never design a loop. :func:`lazy_module` gives a stand-in whose first attribute access
imports the module; type checkers see the real module through ``TYPE_CHECKING``::

    if TYPE_CHECKING:
        import control as ct
    else:
        ct = lazy_module("control")
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any


class _LazyModule:
    """Stands for the module ``name`` until an attribute is asked for; then imports it (once: the
    import system keeps it in ``sys.modules``) and answers from it."""

    __slots__ = ("_name",)

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attr: str) -> Any:
        module: ModuleType = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self) -> str:
        return f"<lazy module {self._name!r}>"


def lazy_module(name: str) -> Any:
    """A stand-in for the module ``name`` (absolute, e.g. ``"scipy.signal"``) that imports it on the
    first attribute access; an unknown name raises ``ModuleNotFoundError`` there, not here."""
    return _LazyModule(name)
