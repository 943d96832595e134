"""The shaper node's update policy: who may change the active shaper, and how a change applies.

Every change of the active shaper names its source (``parameters`` for the node's own
parameters, else the request's ``source``: ``user``, ``identification``, ``learner``,
``scheduler``...; an empty source is ``service``). The policy decides, before anything changes:

- **who**: only sources in ``allowed_sources`` may change the shaper; the last accepted change
  wins;
- **what**: one check for every path that sets the shaper (parameters, ``~/set_shaper``, the
  scheduler, the learner, identification): :func:`check_design` refuses a design mode outside
  :data:`FREQUENCY_RANGE_HZ` or not below ``command_rate`` / :data:`RATE_FACTOR`, an ``si``
  insensitivity below :data:`MIN_INSENSITIVITY`, and a shaper shorter than one command period
  (other than the identity: the FIR could not represent it, :func:`check_representable`);
- **how**: a change from a source in ``retime_sources`` re-times the motion already commanded
  (the impulses still pending follow the new shaper: the mode moved, e.g. the scheduler's
  pose-dependent shaper), any other change switches bumplessly (the motion already commanded
  keeps the shaper it started with);
- **when**: a bumpless switch keeps the old filters alive until their response has passed; with
  :data:`~.fir.MAX_STAGES` of them alive in a filter, a further switch is refused until they
  retire ("still settling"), so that a flood of changes cannot grow the filter without bound.
  Re-timing replaces the pending response and needs no new stage.

:meth:`UpdatePolicy.decide` returns how the change applies or raises :class:`PolicyError` with
the reason; the node then builds the new filter and swaps it in (validate, then commit).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from .fir import MAX_STAGES
from .types import MAX_INSENSITIVITY, Mode, Shaper, ShaperError

#: the source of a request that names none
DEFAULT_SOURCE = "service"
#: the source of a change made through the node's parameters
PARAMETERS_SOURCE = "parameters"

How = Literal["switch", "retime"]

#: Hz, the natural frequencies a designed shaper's modes may have (the shaper.frequency_hz range)
FREQUENCY_RANGE_HZ = (0.01, 1000.0)
#: a designed shaper's modes lie below command_rate / RATE_FACTOR: above it a mode's half period
#: spans fewer than two command periods and the discretised FIR no longer cancels it
RATE_FACTOR = 4.0
#: the least si insensitivity (band width / design frequency) a shaper may have (the parameter's)
MIN_INSENSITIVITY = 0.01


class PolicyError(ValueError):
    """A change the update policy refuses; the message says why."""


def check_representable(shaper: Shaper, rate: float) -> None:
    """Raise :class:`PolicyError` if ``shaper`` (other than the identity) is shorter than one command
    period at ``rate`` (Hz): the FIR could not represent it. Also the check of a shaper used for
    one whole trajectory only (the shaper node's ``action.scheduler``)."""
    if shaper.family != "none" and shaper.duration > 0 and shaper.duration * rate < 1.0:
        raise PolicyError(f"shaper duration {shaper.duration * 1e3:.3g} ms is shorter than one"
                          f" command period ({1e3 / rate:.3g} ms)")


def check_modes(family: str, modes: Iterable[Mode], rate: float, name: str = "design mode") -> None:
    """Raise :class:`~.types.ShaperError` if a design mode of a ``family`` shaper (other than
    ``none`` and ``custom``, whose modes are labels) is outside :data:`FREQUENCY_RANGE_HZ` or not
    below ``rate`` / :data:`RATE_FACTOR` (``rate``: the command rate, Hz). ``name`` names the
    modes in the message (a parameter's name)."""
    if family in ("none", "custom"):
        return
    lo, hi = FREQUENCY_RANGE_HZ
    for m in modes:
        if not lo <= m.hz <= hi:
            raise ShaperError(f"{name} {m.hz:.6g} Hz is outside [{lo:g}, {hi:g}] Hz")
        if m.hz >= rate / RATE_FACTOR:
            raise ShaperError(f"{name} {m.hz:.6g} Hz is too high for command_rate {rate:g} Hz"
                              f" (must be below rate / {RATE_FACTOR:g} = {rate / RATE_FACTOR:g} Hz)")


def check_design(shaper: Shaper, rate: float, name: str = "design mode") -> None:
    """The one check of a shaper about to become active or to shape a goal, whatever path it came
    by (parameters, ``~/set_shaper``, scheduler, learner, identification): its modes
    (:func:`check_modes`), its ``si`` insensitivity (at least :data:`MIN_INSENSITIVITY`) and its
    duration (:func:`check_representable`, first). ``rate``: the command rate, Hz.

    Raises
    ------
    ShaperError
        A mode or the insensitivity is out of range (the message names it).
    PolicyError
        The shaper is shorter than one command period.
    """
    check_representable(shaper, rate)
    check_modes(shaper.family, shaper.modes, rate, name)
    insensitivity = shaper.params.get("insensitivity")
    if insensitivity is not None and not MIN_INSENSITIVITY <= float(insensitivity) <= MAX_INSENSITIVITY:
        raise ShaperError(f"insensitivity {float(insensitivity):g} is outside [{MIN_INSENSITIVITY:g},"
                          f" {MAX_INSENSITIVITY:g}]")


@dataclass(frozen=True)
class UpdatePolicy:
    """Who may change the shaper and how (see the module docstring).

    Attributes
    ----------
    allowed_sources : frozenset of str
        Sources that may change the active shaper.
    retime_sources : frozenset of str
        Sources whose changes re-time the motion already commanded.
    max_stages : int
        Filters a bumpless switch may keep alive at once.
    """

    allowed_sources: frozenset[str]
    retime_sources: frozenset[str] = frozenset()
    max_stages: int = MAX_STAGES

    @classmethod
    def of(cls, allowed: Iterable[str], retime: Iterable[str] = ()) -> UpdatePolicy:
        return cls(frozenset(allowed), frozenset(retime))

    @staticmethod
    def source_of(requested: str) -> str:
        """The source a request stands for (its own, stripped; :data:`DEFAULT_SOURCE` if empty)."""
        return requested.strip() or DEFAULT_SOURCE

    def how(self, source: str) -> How:
        """How a change from ``source`` applies: ``"retime"`` or ``"switch"``."""
        return "retime" if source in self.retime_sources else "switch"

    def allow(self, source: str) -> None:
        """Raise :class:`PolicyError` unless ``source`` may change the shaper."""
        if source not in self.allowed_sources:
            raise PolicyError(f"update policy: source {source!r} is not in allowed_sources"
                              f" {sorted(self.allowed_sources)}")

    def settled(self, stages: Iterable[int]) -> None:
        """Raise :class:`PolicyError` when a filter already keeps ``max_stages`` shapers alive."""
        busiest = max(stages, default=0)
        if busiest >= self.max_stages:
            raise PolicyError(f"{busiest} shaper changes are still settling; try again shortly")

    def decide(self, source: str, shaper: Shaper, rate: float, stages: Iterable[int]) -> How:
        """Check a change of the active shaper to ``shaper`` by ``source``.

        Parameters
        ----------
        source : str
            Who asks.
        shaper : Shaper
            The new shaper, already designed and validated.
        rate : float
            The node's command rate, Hz.
        stages : iterable of int
            The number of shapers alive in each of the node's filters.

        Returns
        -------
        "switch" or "retime"
            How the change applies.

        Raises
        ------
        PolicyError
            The source may not change the shaper, the shaper is shorter than one command period,
            or a switch would exceed the stage limit.
        ShaperError
            A design mode or parameter is out of range (:func:`check_design`).
        """
        self.allow(source)
        check_design(shaper, rate)
        how = self.how(source)
        if how == "switch":
            self.settled(stages)
        return how
