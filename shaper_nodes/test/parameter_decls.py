"""Test helper: the parameter declarations of every executable, as the reference generator collects
them (``scripts/parameters_doc.py``, loaded by path: it sits above both packages)."""

from __future__ import annotations

import importlib.util
import pathlib
from types import ModuleType

ROOT = pathlib.Path(__file__).resolve().parents[2]


def generator() -> ModuleType:
    """The module ``scripts/parameters_doc.py``."""
    spec = importlib.util.spec_from_file_location("parameters_doc_script", ROOT / "scripts" / "parameters_doc.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
