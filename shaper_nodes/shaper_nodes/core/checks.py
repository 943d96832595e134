"""Input checks with errors that name the problem.

Every check raises :class:`InputError` whose ``kind`` is one of :data:`KINDS`, so that nodes can
count, throttle and report rejections per class.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

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
)


class InputError(ValueError):
    """Bad input data; ``kind`` names the class of problem (see :data:`KINDS`)."""

    def __init__(self, kind: str, message: str) -> None:
        if kind not in KINDS:
            raise ValueError(f"unknown input error kind {kind!r}")
        super().__init__(message)
        self.kind = kind


def finite_array(name: str, values: Sequence[float] | np.ndarray, size: int | None = None) -> np.ndarray:
    """Return ``values`` as a float array after checking its size and that all are finite.

    Parameters
    ----------
    name : str
        What the values are, for the error message (e.g. ``"data"``, ``"point 3 positions"``).
    values : sequence of float
        The values.
    size : int, optional
        Required number of values.
    """
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        raise InputError("empty", f"{name} is empty")
    if size is not None and arr.size != size:
        raise InputError("wrong_size", f"{name} has {arr.size} values, expected {size}")
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.flatnonzero(bad.ravel())
        raise InputError(
            "non_finite",
            f"{name} has non-finite values at index {idx[:5].tolist()}"
            f" ({float(arr.ravel()[idx[0]])!r} first)",
        )
    return arr


def joint_permutation(configured: Sequence[str], received: Sequence[str]) -> np.ndarray:
    """Indices ``p`` such that ``received_values[p]`` is in the configured joint order.

    Raises
    ------
    InputError
        ``empty``, ``duplicate_joint``, ``unknown_joint`` or ``missing_joint``.
    """
    received = list(received)
    if not received:
        raise InputError("empty", "joint_names is empty")
    if len(set(received)) != len(received):
        dups = sorted({n for n in received if received.count(n) > 1})
        raise InputError("duplicate_joint", f"duplicate joint names {dups}")
    unknown = [n for n in received if n not in configured]
    if unknown:
        raise InputError("unknown_joint", f"unknown joint names {unknown}; expected {list(configured)}")
    missing = [n for n in configured if n not in received]
    if missing:
        raise InputError("missing_joint", f"missing joint names {missing}")
    index = {n: i for i, n in enumerate(received)}
    return np.array([index[n] for n in configured], dtype=int)


def strictly_increasing(name: str, times: np.ndarray) -> np.ndarray:
    """Check that ``times`` (s) are finite and strictly increasing."""
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        raise InputError("empty", f"{name} is empty")
    if not np.all(np.isfinite(times)):
        raise InputError("non_finite", f"{name} has non-finite values")
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        i = int(np.flatnonzero(steps <= 0.0)[0])
        raise InputError(
            "non_increasing_time",
            f"{name} not strictly increasing: {times[i]:.6g} s at index {i} then {times[i + 1]:.6g} s",
        )
    return times
