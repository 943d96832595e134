"""Numbers in report texts: an uncertainty that is unknown or zero is said, never printed as ``± 0.000``,
and a value that is not a number is "n/a", never ``nan``."""

from __future__ import annotations

import math


def value(x: float | None, spec: str = ".4g", unit: str = "") -> str:
    """``x`` formatted (with `` unit``), or "n/a" when it is None or not finite."""
    if x is None or not math.isfinite(x):
        return "n/a"
    return f"{format(x, spec)}{' ' + unit if unit else ''}"


def plus_minus(x: float | None, std: float | None, spec: str = ".4g", std_spec: str = ".2g", unit: str = "",
               sign: str = "±") -> str:
    """``x ± std unit``; "x unit (uncertainty unknown)" when ``std`` is None, not finite or zero (an
    identification that gives no uncertainty, e.g. a value taken from elsewhere); "n/a" when ``x`` is not."""
    if x is None or not math.isfinite(x):
        return "n/a"
    u = f" {unit}" if unit else ""
    if std is None or not math.isfinite(std) or std <= 0.0:
        return f"{format(x, spec)}{u} (uncertainty unknown)"
    return f"{format(x, spec)} {sign} {format(std, std_spec)}{u}"
