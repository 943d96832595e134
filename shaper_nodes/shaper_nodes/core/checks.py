"""The one home of the core's checks of numbers and arrays, with errors that name the problem.

Two kinds of checks live here:

- checks of incoming data (:func:`finite_array`, :func:`joint_permutation`,
  :func:`strictly_increasing`) raise :class:`InputError`, whose ``kind`` is one of
  :data:`KINDS`, so that nodes can count, throttle and report rejections per class;
- checks of configuration values (:func:`number`, :func:`finite`, :func:`integer`,
  :func:`in_range`, :func:`finite_values`) raise the error class the caller gives (each core
  package has its own, e.g. ``ShaperError`` or ``ListError``, all subclasses of ``ValueError``),
  so that a refusal says which parameter is wrong and why.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

KINDS = (
    "empty",
    "non_finite",
    "wrong_size",
    "unknown_joint",
    "missing_joint",
    "duplicate_joint",
    "non_increasing_time",
    "inconsistent_fields",
    "invalid_shaper",
    "unsupported",
    "too_large",
    "beyond_limits",
    "malformed",
)


#: most joint names a message may carry (refused before they are looked at)
MAX_JOINT_NAMES = 1000


class InputError(ValueError):
    """Bad input data; ``kind`` names the class of problem (see :data:`KINDS`)."""

    def __init__(self, kind: str, message: str) -> None:
        if kind not in KINDS:
            raise ValueError(f"unknown input error kind {kind!r}")
        super().__init__(message)
        self.kind = kind


def finite_array(name: str, values: Sequence[float] | np.ndarray, size: int | None = None,
                 limit: float = math.inf) -> np.ndarray:
    """Return ``values`` as a float array after checking its size, that all are finite and within ``limit``.

    Parameters
    ----------
    name : str
        What the values are, for the error message (e.g. ``"data"``, ``"point 3 positions"``).
    values : sequence of float
        The values.
    size : int, optional
        Required number of values.
    limit : float, optional
        Largest magnitude allowed (``too_large`` beyond it): finite values so large that they are
        implausible, refused before they reach a filter's state or overflow its sums.
    """
    if size is not None and not isinstance(values, np.ndarray) and len(values) != size:  # before converting
        if len(values) == 0:
            raise InputError("empty", f"{name} is empty")
        raise InputError("wrong_size", f"{name} has {len(values)} values, expected {size}")
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        raise InputError("empty", f"{name} is empty")
    if size is not None and arr.size != size:
        raise InputError("wrong_size", f"{name} has {arr.size} values, expected {size}")
    # the usual case in one reduction: the largest magnitude is NaN if any value is, and beyond a finite
    # limit if any value is infinite or too large; only then are the checks below made, for the reason
    if limit < math.inf and np.abs(arr).max() <= limit:
        return arr
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.flatnonzero(bad.ravel())
        raise InputError(
            "non_finite",
            f"{name} has non-finite values at index {idx[:5].tolist()}"
            f" ({float(arr.ravel()[idx[0]])!r} first)",
        )
    if limit < math.inf:
        over = np.abs(arr) > limit
        if over.any():
            k = int(np.flatnonzero(over.ravel())[0])
            raise InputError("too_large", f"{name} has {float(arr.ravel()[k])!r} at index {k}, beyond the limit"
                             f" of {limit:g} in magnitude")
    return arr


def joint_permutation(configured: Sequence[str], received: Sequence[str]) -> np.ndarray:
    """Indices ``p`` such that ``received_values[p]`` is in the configured joint order.

    Raises
    ------
    InputError
        ``empty``, ``duplicate_joint``, ``unknown_joint`` or ``missing_joint``.
    """
    if len(received) > MAX_JOINT_NAMES:  # before any work on them: a message of many names must not stall the node
        raise InputError("too_large", f"{len(received)} joint names exceed the limit of {MAX_JOINT_NAMES}"
                         f" ({len(configured)} joints are shaped here)")
    received = list(received)
    if not received:
        raise InputError("empty", "joint_names is empty")
    counts = Counter(received)  # O(n): a message of many names must not stall the node
    if len(counts) != len(received):
        dups = sorted(n for n, c in counts.items() if c > 1)
        raise InputError("duplicate_joint", f"duplicate joint names {_few(dups)} ({len(received)} names)")
    known = set(configured)
    unknown = [n for n in received if n not in known]
    if unknown:
        raise InputError("unknown_joint", f"unknown joint names {_few(unknown)}; expected {list(configured)}")
    missing = [n for n in configured if n not in counts]
    if missing:
        raise InputError("missing_joint", f"missing joint names {missing}")
    index = {n: i for i, n in enumerate(received)}
    return np.array([index[n] for n in configured], dtype=int)


def _few(names: list[str], most: int = 10) -> str:
    """At most ``most`` names for a message, and how many more there are."""
    return str(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def strictly_increasing(name: str, times: np.ndarray) -> np.ndarray:
    """Check that ``times`` (s) are finite and strictly increasing."""
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        raise InputError("empty", f"{name} is empty")
    if not np.all(np.isfinite(times)):
        raise InputError("non_finite", f"{name} has non-finite values")
    # compared, not subtracted: the difference of two finite times may overflow (1.7e308 - -1.7e308)
    back = times[1:] <= times[:-1]
    if np.any(back):
        i = int(np.flatnonzero(back)[0])
        raise InputError(
            "non_increasing_time",
            f"{name} not strictly increasing: {times[i]:.6g} s at index {i} then {times[i + 1]:.6g} s",
        )
    return times


# ----------------------------------------------------------------------------- configuration values


def number(name: str, value: Any, error: type[ValueError] = ValueError) -> float:
    """``value`` as a float; booleans and non-numbers are refused (NaN and infinities pass)."""
    if isinstance(value, (bool, np.bool_)):
        raise error(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None


def finite(name: str, value: Any, error: type[ValueError] = ValueError) -> float:
    """``value`` as a finite float."""
    x = number(name, value, error)
    if not math.isfinite(x):
        raise error(f"{name} must be finite, got {value!r}")
    return x


def in_range(name: str, value: Any, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False,
             hi_open: bool = False, error: type[ValueError] = ValueError, unit: str = "") -> float:
    """``value`` as a finite float in the interval from ``lo`` to ``hi`` (closed unless ``*_open``)."""
    x = finite(name, value, error)
    below = x <= lo if lo_open else x < lo
    above = x >= hi if hi_open else x > hi
    if below or above:
        left, right = "(" if lo_open else "[", ")" if hi_open else "]"
        raise error(f"{name} must be in {left}{lo:g}, {hi:g}{right}{' ' + unit if unit else ''}, got {value!r}")
    return x


def integer(name: str, value: Any, lo: int | None = None, hi: int | None = None,
            error: type[ValueError] = ValueError) -> int:
    """``value`` as an int (an integral float such as 3.0 is taken; booleans are not) in [lo, hi]."""
    ok = not isinstance(value, (bool, np.bool_))
    try:
        ok = ok and float(value).is_integer()
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise error(f"{name} must be an integer, got {value!r}")
    n = int(value)
    if (lo is not None and n < lo) or (hi is not None and n > hi):
        bounds = f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
        raise error(f"{name} must be an integer in {bounds}, got {value!r}")
    return n


def finite_values(name: str, values: Any, error: type[ValueError] = ValueError) -> npt.NDArray[np.float64]:
    """``values`` as a flat float array, every value finite (an empty sequence passes)."""
    try:
        v = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        raise error(f"{name} must be numbers, got {values!r}") from None
    if not np.all(np.isfinite(v)):
        raise error(f"{name} must be finite, got {v.tolist()}")
    return v
