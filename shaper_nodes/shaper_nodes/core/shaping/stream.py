"""The rules of the shaper node's streamed commands, free of ROS: what may go in, what may come out.

The shaper node is the last software before a robot's controller. Its streamed inputs (one sample,
a block of samples, or a few trajectory points per message) are shaped here by :class:`CommandStream`,
which holds their filters and enforces, on every path:

Inputs
    finite, at most ``max_abs`` in magnitude (a larger, finite value is implausible and never reaches
    a filter's state), of one value per joint, and positions within the joint limits (a sample inside
    them whose first impulse stays inside would otherwise pull every later output out). A stream
    point's times (time_from_start, s) are non-negative and strictly increasing (:func:`check_times`).
    A stream message's header stamp is normalised (:func:`normal_stamp`: a ``nanosec`` of 1e9 or more
    carried into ``sec``) and, when not zero (zero: "start now"), never earlier than the last accepted
    non-zero stamp (a controller given a stamp that goes back would replace the trajectory it runs
    with one that started in its past).
Outputs
    finite and within the joint limits (:class:`~shaper_nodes.core.shaping.limits.JointLimits`): an
    output can leave them although its inputs did not (a switch between shapers, a custom shaper with
    negative impulses). Then nothing is passed on, and the filters of that input restart at rest at the
    last command they passed on; the next sample is shaped from there (refusing the sample while keeping
    the filters' state would refuse every later one too). The reset replaces all the state a sample
    changes, so nothing of the refused sample stays.
Refusals
    raise :class:`~shaper_nodes.core.checks.InputError` whose ``kind`` names the class; a refused input
    leaves the filters as they were (or reset, as above).

Fields of trajectory points follow what arrives: a field that appears (velocities, say) starts its
filter at its first value (there was no output of it to be continuous with); a field that goes away
stops being output, and its filter starts afresh if it comes back.

Blocks: a Float64MultiArray whose layout has two dimensions, [samples, joints], carries consecutive
samples (the sim plant's lockstep exchange); :func:`shaper_nodes.core.lockstep.block_rows` tells
their number from the layout's sizes, and :meth:`CommandStream.shape_block` shapes them as those
samples one by one would be.

Threads: :attr:`CommandStream.lock` is held by every call that reads or changes the filters (shaping,
:meth:`CommandStream.switch`, :meth:`CommandStream.stages`), so a shaper change lands between two
samples; a holder of the lock stalls the stream.
"""

from __future__ import annotations

import array
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from operator import lt
from typing import Any

import numpy as np

from shaper_nodes.core.checks import InputError, finite_array, strictly_increasing

from .fir import RetimingShaper, StreamingShaper
from .limits import JointLimits, bounds_check
from .sparse_fir import SparseFir

#: the fields of a trajectory point that are shaped, in message order
FIELDS = ("positions", "velocities", "accelerations")

_Filter = StreamingShaper | RetimingShaper


def check_times(times: np.ndarray, require_order: bool = False) -> None:
    """The time rule of trajectory points: ``times`` (time_from_start, s, shape (N,)) are non-negative,
    and finite and strictly increasing when there are several or ``require_order``.

    Raises
    ------
    InputError
        ``non_increasing_time`` (a negative time, or times out of order), ``non_finite`` or ``empty``.
    """
    t = times.tolist()
    if len(t) == 1 and not require_order and t[0] >= 0.0:  # the stream's usual point, cheaply
        return
    if len(t) > 1 and t[0] >= 0.0 and all(map(lt, t, t[1:])) and math.isfinite(t[-1]):
        return
    if np.any(times < 0):
        k = int(np.argmax(times < 0))
        raise InputError("non_increasing_time", f"time_from_start of point {k} is negative ({times[k]:g} s)")
    if require_order or len(times) > 1:
        strictly_increasing("time_from_start", times)


NS = 1_000_000_000
INT32 = (-(2**31), 2**31 - 1)


def normal_stamp(sec: int, nanosec: int) -> tuple[int, int]:
    """A ``sec``/``nanosec`` pair (a header stamp or a duration) with ``nanosec`` in [0, 1e9).

    Raises
    ------
    InputError
        ``too_large`` when the carried ``sec`` leaves the int32 range of the message field.
    """
    if 0 <= nanosec < NS:
        return sec, nanosec
    carry, rest = divmod(int(nanosec), NS)
    if not INT32[0] <= sec + carry <= INT32[1]:
        raise InputError("too_large", f"stamp {sec} s + {nanosec} ns does not fit the message's int32 seconds")
    return sec + carry, rest


class CommandStream:
    """The streamed commands of the shaper node: their filters and the rules of the module docstring.

    Parameters
    ----------
    fir : SparseFir
        The active filter at the start.
    limits : JointLimits
        The joint limits of inputs and outputs; their ``names`` are the joints, in order.
    retiming : bool
        Whether the filters can re-time (:class:`RetimingShaper`, needed by :meth:`switch` with
        ``retime``) or switch bumplessly only (:class:`StreamingShaper`).
    max_abs : float
        Largest magnitude of an input value (positions rad or m, velocities and accelerations in their SI
        units); may be changed at any time (``limits.max_abs_value``).
    max_samples : int
        Most samples of a block (``limits.max_trajectory_samples``); may be changed at any time.

    Attributes
    ----------
    array_filter : StreamingShaper or RetimingShaper
        The filter of the single samples and blocks (Float64MultiArray).
    field_filters : dict of str to StreamingShaper or RetimingShaper
        The filters of the trajectory points' fields (:data:`FIELDS`).
    fields : tuple of str
        The fields the last accepted trajectory point carried.
    lock : threading.Lock
        Held by every call that reads or changes the filters.
    """

    def __init__(self, fir: SparseFir, limits: JointLimits, *, retiming: bool = False, max_abs: float = math.inf,
                 max_samples: int = 5_000) -> None:
        filt = RetimingShaper if retiming else StreamingShaper
        self.limits = limits
        self.joints = len(limits.names)
        self.max_abs = float(max_abs)
        self.max_samples = int(max_samples)
        self.array_filter: _Filter = filt(fir, self.joints)
        self.field_filters: dict[str, _Filter] = {f: filt(fir, self.joints) for f in FIELDS}
        self.fields: tuple[str, ...] = ()
        self.lock = threading.Lock()
        # the last command passed on per filter ("array", "stream.<field>"), where a refused output restarts it
        self._last_sent: dict[str, np.ndarray | list[float]] = {}
        self._bounds_for = -1.0  # the max_abs of _bounds and _within_in (see input_bounds)
        self._bounds: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())
        # the streamed sample's checks, written out per joint (limits.bounds_check): its input's, made with _bounds,
        # and its output's (finite, within the position limits)
        self._within_in: Callable[[Sequence[float]], bool] = lambda v: False
        self._within_out = bounds_check(*limits.sample_bounds)
        self.last_stamp_ns = 0  # the last accepted non-zero header stamp of the stream, ns (0: none yet)

    @property
    def input_bounds(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Per joint, the (lowest, highest) value a streamed position may take (``max_abs`` and the
        position limits; see :meth:`shape_array`), recomputed when ``max_abs`` changes."""
        self._input_check()
        return self._bounds

    def _input_check(self) -> Callable[[Sequence[float]], bool]:
        """The streamed sample's input check with the bounds of :attr:`input_bounds` (made again when ``max_abs``
        changes): ``lo <= v <= hi`` per value, one value per joint."""
        max_abs = self.max_abs
        if self._bounds_for != max_abs:
            self._bounds = self.limits.input_bounds(max_abs)
            self._within_in = bounds_check(*self._bounds)
            self._bounds_for = max_abs
        return self._within_in

    # ------------------------------------------------------------------ shaping
    def shape_array(self, data: Sequence[float] | array.array[float] | np.ndarray) -> list[float]:
        """One sample (one value per joint, positions) shaped by the array filter, with the checks and
        refusals of :meth:`shape_block`, made cheaply for a few values: the input is finite, within
        ``max_abs`` and within the position limits exactly when ``lo <= v <= hi`` holds for each value
        with the bounds of :attr:`input_bounds` (a NaN fails any comparison), and the output is finite
        and within the position limits exactly when it holds with :attr:`JointLimits.sample_bounds`. Only
        a sample that fails is checked again by the general checks, which raise the InputError naming the
        reason. The sample stays a list of Python floats through the filter
        (:meth:`StreamingShaper.process_values`): on 7 values numpy's calls cost more than the arithmetic.
        Holds :attr:`lock`. Returns the shaped values."""
        return self.shape_values(data.tolist() if isinstance(data, array.array) else list(data))

    def shape_values(self, values: Sequence[float]) -> list[float]:
        """:meth:`shape_array` for a sample given as a tuple or a new list of Python floats (the streamed sample's
        path: no conversion, no copy)."""
        with self.lock:
            within = self._within_in if self._bounds_for == self.max_abs else self._input_check()
            # lo <= v <= hi per value, and one value per joint, written out (limits.bounds_check); a NaN compares False
            if not within(values):
                # the reason, as the general checks give it
                x = finite_array("data", values, size=self.joints, limit=self.max_abs)
                self.limits.check("positions", "the command", x)
                values = x.tolist()
            out = self.array_filter.process_values(values)
            if not self._within_out(out):
                self._check_shaped({"array": (self.array_filter, np.array(values), "positions")},
                                   {"array": np.array(out)})
            self._last_sent["array"] = out
            return out

    def shape_block(self, data: Sequence[float] | array.array[float] | np.ndarray, rows: int) -> list[float]:
        """A block of ``rows`` consecutive samples (row-major, samples x joints, positions) shaped by the
        array filter in one call of its block path: inputs finite, within ``max_abs`` and the position
        limits, outputs finite and within the position limits; a block with any sample refused is refused
        whole, and nothing of it stays in the filter. Holds :attr:`lock`. Returns the shaped values,
        row-major."""
        x = finite_array("data", data, size=rows * self.joints, limit=self.max_abs).reshape(rows, self.joints)
        with self.lock:
            out = self._shape_checked({"array": (self.array_filter, x, "positions")})
        values: list[float] = out["array"].ravel().tolist()
        return values

    def shape_points(self, times: np.ndarray, fields: Mapping[str, np.ndarray],
                     stamp: tuple[int, int] = (0, 0)) -> dict[str, np.ndarray]:
        """Trajectory points shaped field by field: ``times`` (N,) their time_from_start, s (checked by
        :func:`check_times`), ``fields`` maps each field the points carry (of :data:`FIELDS`; positions
        always) to its values (N, joints), in joint order, already finite and within ``max_abs`` (the
        caller's conversion checks them), ``stamp`` the message's header stamp, normalised
        (:func:`normal_stamp`), checked against the last one accepted (module docstring). A field that
        appears starts its filter at its first value; a field that vanishes stops, and starts afresh if it
        comes back. Holds :attr:`lock`. Returns the shaped values per field, (N, joints) each."""
        check_times(times)
        stamp_ns = stamp[0] * NS + stamp[1]
        if stamp_ns != 0 and stamp_ns < self.last_stamp_ns:
            raise InputError("non_increasing_time", f"header stamp {stamp_ns / NS:.9f} s is before the last accepted"
                             f" one, {self.last_stamp_ns / NS:.9f} s: a stream's stamps may not go back (0 = now)")
        unknown = [f for f in fields if f not in self.field_filters]
        if unknown:
            raise InputError("unsupported", f"fields {unknown} are not shaped (only {list(FIELDS)})")
        with self.lock:
            for f in fields:
                if f not in self.fields:  # a field that (re)appears starts at its first value
                    self.field_filters[f].reset()
                    self._last_sent.pop(f"stream.{f}", None)
            shaped = self._shape_checked({f"stream.{f}": (self.field_filters[f], v, f) for f, v in fields.items()})
            names = tuple(fields)
            for f in self.fields:
                if f not in names:  # gone: if it comes back it starts afresh
                    self.field_filters[f].reset()
                    self._last_sent.pop(f"stream.{f}", None)
            self.fields = names
            if stamp_ns != 0:
                self.last_stamp_ns = stamp_ns
        return {f: shaped[f"stream.{f}"] for f in names}

    def _shape_checked(self, work: dict[str, tuple[_Filter, np.ndarray, str]]) -> dict[str, np.ndarray]:
        """Shape streamed samples with the output invariants held; ``work`` maps a key to (filter,
        samples, field: "positions", "velocities" or "accelerations"). Inputs beyond the joint limits are
        refused before any filter; then each filter runs and its output is checked
        (:meth:`_check_shaped`). Raises the InputError. Call with :attr:`lock` held."""
        for _, (_, x, field) in work.items():
            self.limits.check(field, "the command", x)
        out = {k: f.process(x) for k, (f, x, _) in work.items()}
        self._check_shaped(work, out)
        for k, y in out.items():
            self._last_sent[k] = np.atleast_2d(y)[-1].copy()
        return out

    def _check_shaped(self, work: Mapping[str, tuple[_Filter, Any, str]], out: Mapping[str, np.ndarray]) -> None:
        """Check the filters' outputs ``out`` (finite, within the limits). On a violation the filters of
        ``work`` restart at rest at the last command they passed on, and the InputError is raised."""
        try:
            for k, y in out.items():
                if not np.all(np.isfinite(y)):
                    raise InputError("non_finite", f"the shaped {work[k][2]} would not be finite")
                self.limits.check(work[k][2], "the shaped command", y)
        except InputError as err:
            for k, (f, _, _) in work.items():
                f.reset(self._last_sent.get(k))  # type: ignore[arg-type]  # a list is taken as an array
            raise InputError(err.kind, f"{err}; the filters restart from the last command passed on") from None

    # ------------------------------------------------------------------ shaper changes
    def switch(self, fir: SparseFir, retime: bool = False) -> None:
        """Every filter to ``fir`` between two samples: bumplessly (the motion already commanded keeps
        the old filter), or with ``retime`` re-timing it (only with ``retiming`` filters)."""
        with self.lock:
            for f in (self.array_filter, *self.field_filters.values()):
                if retime:
                    if not isinstance(f, RetimingShaper):
                        raise ValueError("retime needs a CommandStream made with retiming=True")
                    f.retime(fir)
                else:
                    f.switch(fir)

    def stages(self) -> list[int]:
        """The filters alive in each stream filter (the array filter's first): the active one plus retired
        ones whose tails still run."""
        with self.lock:
            return [f.stages for f in (self.array_filter, *self.field_filters.values())]
