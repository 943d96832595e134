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


def plus_minus_fixed(x: float, std: float, decimals: int) -> str:
    """``x +- std`` in fixed notation, the uncertainty to two significant digits and the value to the same
    decimal place (at least ``decimals``), so that a small uncertainty never prints as 0.000; "x (uncertainty
    unknown)" when ``std`` is zero or not finite (a table's column of values, aligned by ``decimals``)."""
    if not math.isfinite(x):
        return "n/a"
    if not (std > 0 and math.isfinite(std)):
        return f"{x:.{decimals}f} (uncertainty unknown)"
    decimals = max(decimals, 1 - math.floor(math.log10(std)))
    return f"{x:.{decimals}f} +- {std:.{decimals}f}"


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun``, with an "s" unless ``n`` is 1: "1 recording", "5 recordings", "0 robots"."""
    return f"{n} {noun if n == 1 else noun + 's'}"
