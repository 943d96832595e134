"""Per-move learned state: one entry per move of a cycle, keyed by the move's identity, saved whole.

A pick-and-place cycle is a sequence of moves that end at different poses, where the robot's
modes differ; what is learned for one move (a LIST shaper factor, a time-scaling factor) does not
suit another. :class:`MoveStore` keeps one :class:`MoveEntry` per move:

- **identity** (:func:`move_key`): a name when the cell gives one (a ``/cycle_events`` segment's
  move name), otherwise the start and goal joint positions rounded to :data:`KEY_DECIMALS`
  decimals of a radian (a FollowJointTrajectory goal's first and last point), so that the same
  taught move maps to the same entry cycle after cycle and a new move gets a new one;
- **what was learned**: the LIST learner's state (:meth:`ListLearner.to_dict`), the impulses of
  the correction applied to the move (a factor over the base shaper, or the whole shaper when
  there is no base), what the move started from (``schedule``, ``design``, ``identified``), the
  base's and the best cycle's measures (to keep a correction only when it pays: ``residual_rms``, and
  ``move_settle_s`` where the learner measures it), and the
  time-scaling learner's state (:class:`~.speed.SpeedLearner`).

:meth:`MoveStore.to_doc` gives a versioned JSON-ready document; :meth:`MoveStore.save` writes it
atomically (:func:`~shaper_nodes.core.learning.state_file.write_state`); :func:`store_from_doc` reads
it back entry by entry, each checked (the key against the poses, the LIST and speed states through
their own checks): a broken entry is left out with the reason and its move starts afresh, as a
learner with a broken state file does. ROS-free: the learner node and the reproduction
(``reproductions.arm_learning``) share it.
"""

from __future__ import annotations

import hashlib
import math
import pathlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .list import ListError, ListLearner
from .speed import SpeedError, SpeedLearner
from .state_file import write_state

__all__ = ["KEY_DECIMALS", "MOVES_FORMAT", "MOVES_VERSION", "TIME_TOLERANCE_S", "MoveEntry", "MoveError",
           "MoveStore", "keep_when_it_pays", "move_key", "pays", "store_from_doc"]

#: version of :meth:`MoveStore.to_doc`'s documents
MOVES_VERSION = 1
#: the document's ``format`` entry
MOVES_FORMAT = "shaper_moves"
#: decimals of a radian the poses are rounded to in a move's key (1 mrad: far below a taught point's spacing,
#: far above the controller's end-point error)
KEY_DECIMALS = 3
#: where a move's learning started from
ORIGINS = ("schedule", "design", "identified")

_ENTRY_KEYS = {"key", "name", "start", "goal", "origin", "cycles", "list", "correction", "base", "best", "speed"}
_MEASURE_KEYS = {"residual_rms", "move_settle_s"}


class MoveError(ValueError):
    """A bad move identity or per-move state; the message names the move and the problem."""


def _pose(name: str, value: Any) -> list[float]:
    try:
        q = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise MoveError(f"{name} must be a list of joint positions, got {value!r}") from None
    if q.size == 0 or not np.all(np.isfinite(q)):
        raise MoveError(f"{name} must be non-empty and finite, got {value!r}")
    return [float(x) for x in q]


def move_key(start: Sequence[float] | np.ndarray, goal: Sequence[float] | np.ndarray, name: str | None = None) -> str:
    """The identity of a move: ``name`` if given, else a hash of the start and goal poses (rad) rounded to
    :data:`KEY_DECIMALS` decimals (``pose-`` and 16 hex digits).

    Raises
    ------
    MoveError
        An empty name, or poses that are empty, non-finite or of different lengths.
    """
    if name is not None:
        if not isinstance(name, str) or not name.strip():
            raise MoveError(f"a move's name must be a non-empty string, got {name!r}")
        return name
    a, b = _pose("start", start), _pose("goal", goal)
    if len(a) != len(b):
        raise MoveError(f"start has {len(a)} joints, goal {len(b)}")
    text = ",".join(f"{round(x, KEY_DECIMALS) + 0.0:.{KEY_DECIMALS}f}" for x in a + b)
    return "pose-" + hashlib.sha256(text.encode()).hexdigest()[:16]


def _measures(name: str, value: Any) -> dict[str, float] | None:
    if value is None:
        return None
    if not isinstance(value, Mapping) or not {"residual_rms"} <= set(value) <= _MEASURE_KEYS:
        raise MoveError(f"{name} must have the entry residual_rms (and may have move_settle_s), got {value!r}")
    out = {}
    for k in sorted(value):
        v = value[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)) or v < 0:
            raise MoveError(f"{name}.{k} must be a finite number >= 0, got {v!r}")
        out[k] = float(v)
    return out


def _impulses(value: Any) -> tuple[list[float], list[float]] | None:
    if value is None:
        return None
    if not isinstance(value, Mapping) or set(value) != {"amplitudes", "times"}:
        raise MoveError(f"correction must have amplitudes and times, got {value!r}")
    a, t = np.asarray(value["amplitudes"], dtype=float), np.asarray(value["times"], dtype=float)
    if a.ndim != 1 or a.shape != t.shape or a.size == 0 or not (np.all(np.isfinite(a)) and np.all(np.isfinite(t))):
        raise MoveError("correction amplitudes and times must be finite lists of one length")
    if abs(float(a.sum()) - 1.0) > 1e-6 or t[0] != 0.0 or np.any(np.diff(t) <= 0):
        raise MoveError("correction must sum to 1, start at 0 s and have increasing times")
    return a.tolist(), t.tolist()


@dataclass
class MoveEntry:
    """What is learned for one move (module docstring); times in s, residuals in m/s^2."""

    key: str
    name: str
    start: list[float]
    goal: list[float]
    origin: str = "schedule"
    cycles: int = 0
    list_state: dict[str, Any] | None = None
    correction: tuple[list[float], list[float]] | None = None
    base: dict[str, float] | None = None
    best: dict[str, float] | None = None
    speed_state: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def learner(self) -> ListLearner | None:
        """The LIST learner restored from :attr:`list_state` (None if there is none)."""
        return None if self.list_state is None else ListLearner.from_dict(self.list_state)

    def speed(self) -> SpeedLearner | None:
        """The speed learner restored from :attr:`speed_state` (None if there is none)."""
        return None if self.speed_state is None else SpeedLearner.from_dict(self.speed_state)

    def relearn(self, origin: str) -> None:
        """Forget what was learned (the plant changed): the move starts again from ``origin``."""
        self.origin, self.cycles, self.list_state, self.correction = origin, 0, None, None
        self.base = self.best = None
        if self.speed_state is not None:
            sp = SpeedLearner.from_dict(self.speed_state)
            sp.relearn()
            self.speed_state = sp.to_dict()

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "name": self.name, "start": list(self.start), "goal": list(self.goal),
                "origin": self.origin, "cycles": self.cycles, "list": self.list_state,
                "correction": None if self.correction is None else {"amplitudes": list(self.correction[0]),
                                                                      "times": list(self.correction[1])},
                "base": self.base, "best": self.best, "speed": self.speed_state}

    @classmethod
    def from_dict(cls, d: Any) -> MoveEntry:
        """An entry saved by :meth:`to_dict`, every entry checked (:class:`MoveError` names the problem)."""
        if not isinstance(d, Mapping):
            raise MoveError(f"a move entry must be a dictionary, got {type(d).__name__}")
        if set(d) != _ENTRY_KEYS:
            raise MoveError(f"move entry entries differ: missing {sorted(_ENTRY_KEYS - set(d))},"
                            f" unknown {sorted(set(d) - _ENTRY_KEYS)}")
        if not isinstance(d["name"], str):
            raise MoveError(f"name must be a string, got {d['name']!r}")
        start, goal = _pose("start", d["start"]), _pose("goal", d["goal"])
        key = d["key"]
        if key not in (move_key(start, goal), d["name"]):
            raise MoveError(f"key {key!r} is neither the name {d['name']!r} nor the poses' key"
                            f" {move_key(start, goal)!r}")
        if d["origin"] not in ORIGINS:
            raise MoveError(f"origin must be one of {', '.join(ORIGINS)}, got {d['origin']!r}")
        cycles = d["cycles"]
        if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 0:
            raise MoveError(f"cycles must be an integer >= 0, got {cycles!r}")
        entry = cls(str(key), d["name"], start, goal, d["origin"], cycles, None, _impulses(d["correction"]),
                    _measures("base", d["base"]), _measures("best", d["best"]), None)
        try:
            if d["list"] is not None:
                entry.list_state = ListLearner.from_dict(d["list"]).to_dict()
            if d["speed"] is not None:
                entry.speed_state = SpeedLearner.from_dict(d["speed"]).to_dict()
        except (ListError, SpeedError) as err:
            raise MoveError(str(err)) from None
        return entry


class MoveStore:
    """The learned state of every move seen, keyed by :func:`move_key` (module docstring)."""

    def __init__(self) -> None:
        self._entries: dict[str, MoveEntry] = {}

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[MoveEntry]:
        return iter(self._entries.values())

    def __contains__(self, key: object) -> bool:
        return key in self._entries

    def get(self, key: str) -> MoveEntry | None:
        return self._entries.get(key)

    def entry(self, start: Sequence[float] | np.ndarray, goal: Sequence[float] | np.ndarray,
              name: str | None = None, origin: str = "schedule") -> tuple[MoveEntry, bool]:
        """The move's entry, made (from ``origin``) if the move was not seen before; returns (entry, new)."""
        key = move_key(start, goal, name)
        found = self._entries.get(key)
        if found is not None:
            return found, False
        if origin not in ORIGINS:
            raise MoveError(f"origin must be one of {', '.join(ORIGINS)}, got {origin!r}")
        made = MoveEntry(key, name or key, _pose("start", start), _pose("goal", goal), origin)
        self._entries[key] = made
        return made, True

    def relearn(self, origin: str) -> list[str]:
        """Every move starts learning again from ``origin`` (a payload change, a drift warning); returns the keys."""
        for e in self._entries.values():
            e.relearn(origin)
        return list(self._entries)

    def to_doc(self, saved_at: float | None = None) -> dict[str, Any]:
        """The versioned document of every entry."""
        doc: dict[str, Any] = {"format": MOVES_FORMAT, "version": MOVES_VERSION,
                               "moves": {k: e.to_dict() for k, e in self._entries.items()}}
        if saved_at is not None:
            doc["saved_at"] = float(saved_at)
        return doc

    def save(self, path: pathlib.Path, saved_at: float | None = None) -> None:
        """Write :meth:`to_doc` to ``path`` atomically."""
        write_state(path, self.to_doc(saved_at))


def store_from_doc(doc: Any) -> tuple[MoveStore, dict[str, str]]:
    """The store saved in ``doc`` (:meth:`MoveStore.to_doc`), entry by entry; returns (store, problems):
    the entries that failed their checks are left out, ``problems`` says why per key.

    Raises
    ------
    MoveError
        The document itself is not a moves document of this version (then nothing can be loaded).
    """
    if not isinstance(doc, Mapping):
        raise MoveError(f"the moves state must be a dictionary, got {type(doc).__name__}")
    unknown = set(doc) - {"format", "version", "moves", "saved_at"}
    if unknown:
        raise MoveError(f"unknown entries in the moves state: {sorted(unknown)}")
    if doc.get("format") != MOVES_FORMAT or doc.get("version") != MOVES_VERSION:
        raise MoveError(f"not a {MOVES_FORMAT} document of version {MOVES_VERSION}: format {doc.get('format')!r},"
                        f" version {doc.get('version')!r}")
    moves = doc.get("moves")
    if not isinstance(moves, Mapping):
        raise MoveError(f"moves must be a dictionary, got {type(moves).__name__}")
    store, problems = MoveStore(), {}
    for key, value in moves.items():
        try:
            entry = MoveEntry.from_dict(value)
            if entry.key != key:
                raise MoveError(f"saved under {key!r} but its key is {entry.key!r}")
        except MoveError as err:
            problems[str(key)] = str(err)
            continue
        store._entries[str(key)] = entry
    return store, problems


#: tolerance of the keep rule on a move's move + settle time, s: one sample of the 500 Hz record the settling is
#: measured on (the flange within 0.05 mm, ``move_settle_s``), so a trial that settles in the same or the next
#: sample as the base does not count as slower
TIME_TOLERANCE_S = 0.0021


def pays(measured: Mapping[str, float], base: Mapping[str, float], time_tolerance_s: float = TIME_TOLERANCE_S) -> bool:
    """Whether a trial's measures beat a move's base: a lower residual AND a move + settle time no longer.

    Parameters
    ----------
    measured, base : mapping
        ``residual_rms`` (m/s^2) and, where measured, ``move_settle_s`` (s, to 0.05 mm at the flange).
    time_tolerance_s : float
        How much longer (s) the trial's move + settle time may be and still count as no longer.

    Returns
    -------
    bool
        ``measured["residual_rms"] < base["residual_rms"]`` and, when both have ``move_settle_s``,
        ``measured["move_settle_s"] <= base["move_settle_s"] + time_tolerance_s``.
    """
    if not measured["residual_rms"] < base["residual_rms"]:
        return False
    if "move_settle_s" in measured and "move_settle_s" in base:
        return bool(measured["move_settle_s"] <= base["move_settle_s"] + time_tolerance_s)
    return True


def keep_when_it_pays(entry: MoveEntry, m: float, shaped: bool, learner_best: float | None = None,
                      move_settle_s: float | None = None, time_tolerance_s: float = TIME_TOLERANCE_S) -> str:
    """Whether a move's learned correction pays, after a cycle of residual ``m`` (m/s^2) and, where measured,
    move + settle time ``move_settle_s`` (s, the flange within 0.05 mm).

    The rule, weighing residual and time:

    - the move's cycle without the learned correction (``shaped`` False: the base alone, e.g. the schedule;
      the LIST reference) sets :attr:`MoveEntry.base` and :attr:`MoveEntry.best` to its measures;
    - a cycle with a correction **pays** (:func:`pays`) when its residual is lower than the base's AND its
      move + settle time is not longer than the base's by more than ``time_tolerance_s`` (time is weighed
      only when both cycles measured it); a paying cycle with a lower residual than :attr:`MoveEntry.best`
      becomes the best (the best *kept* state);
    - a cycle that does not pay stops the move's learning at its best kept state: ``"best"`` if a
      correction has paid (:attr:`MoveEntry.best` is not the base's measures), else ``"base"`` (the base
      alone). So a correction is never kept that makes the move slower or leaves more residual than the
      base, and at most one cycle per move (the failed trial) is worse than the base.

    Parameters
    ----------
    entry : MoveEntry
        The move; its ``base`` and ``best`` are updated.
    m : float
        The cycle's residual, m/s^2 (the same measure for every cycle of the move).
    shaped : bool
        Whether the cycle ran with the learned correction.
    learner_best : float, optional
        The learner's best residual (m/s^2). Used only when time is not measured (``move_settle_s`` None)
        and no paying cycle is recorded in ``best`` (e.g. a state saved before ``best`` was kept): then
        ``"best"`` if it beat the base.
    move_settle_s : float, optional
        The cycle's move + settle time, s (None: not measured, the rule weighs the residual alone).
    time_tolerance_s : float
        Tolerance on the move + settle time, s (:data:`TIME_TOLERANCE_S`: one sample of 500 Hz).

    Returns
    -------
    str
        ``"learn"`` (go on), ``"best"`` (hold at the best kept correction) or ``"base"`` (the base alone).
    """
    measured = {"residual_rms": float(m)}
    if move_settle_s is not None:
        measured["move_settle_s"] = float(move_settle_s)
    if not shaped:
        entry.base, entry.best = measured, dict(measured)
        return "learn"
    if entry.base is None:  # nothing to judge against yet
        return "learn"
    if pays(measured, entry.base, time_tolerance_s):
        if entry.best is None or measured["residual_rms"] < entry.best["residual_rms"]:
            entry.best = measured
        return "learn"
    if entry.best is not None and entry.best != entry.base:
        return "best"
    base = entry.base["residual_rms"]
    return "best" if move_settle_s is None and learner_best is not None and learner_best < base else "base"
