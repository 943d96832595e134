# Copyright 2026 The shaper_nodes authors. Licensed under the Apache License, Version 2.0.
"""rclpy's logger refuses a call site whose severity changes between calls (``ValueError: Logger severity cannot
be changed between calls``): ``log = logger.info if ok else logger.error; log(text)`` raises the first time the
other branch is taken, in the callback that was reporting a refusal. No module of the package may do that."""

from __future__ import annotations

import pathlib
import re

from rclpy.logging import get_logger

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "shaper_nodes"
#: a logger method chosen by a condition (``= <...>get_logger().info if``, ``= log.info if ... else log.error``)
CHOSEN = re.compile(r"=\s*[\w.()]*get_logger\(\)\.\w+\s+if\b"
                    r"|=\s*[\w.]*_?log\w*\.\w+\s+if\b.*\belse\s+[\w.]*\.(error|warning|info)")


def test_rclpy_refuses_a_call_site_whose_severity_changes():
    logger = get_logger("test_log_call_sites")
    raised = []
    for ok in (True, False):
        try:
            (logger.info if ok else logger.error)("the same call site, first info, then error")
        except ValueError as e:
            raised.append((ok, str(e)))
    assert raised == [(False, "Logger severity cannot be changed between calls.")]


def test_no_module_chooses_a_logger_method_by_a_condition():
    found = [f"{p.relative_to(PACKAGE)}:{n}" for p in sorted(PACKAGE.rglob("*.py"))
             for n, line in enumerate(p.read_text().splitlines(), 1) if CHOSEN.search(line)]
    assert not found, f"a logger method chosen by a condition, called from one site: {found}"
