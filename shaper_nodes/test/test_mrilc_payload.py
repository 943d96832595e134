# Copyright 2026 The shaper_nodes authors
# SPDX-License-Identifier: Apache-2.0
"""The payload from a drifted mode (core/learning/mrilc/payload.py), on a model of three modes that fall with the
payload as on an arm (f_k(m) = f_k(0) / sqrt(1 + m / M_k)): known masses round-trip, a mode two branches give at
two masses far apart is refused as ambiguous unless the cycle's other modes tell them apart, a mode no mass in the
range gives is refused with the range's modes, bad modes (NaN, negative, 1e9 Hz) and a failing model are refused,
and the work is bounded."""

from __future__ import annotations

import math

import pytest

from shaper_nodes.core.learning.mrilc.model import MrilcError
from shaper_nodes.core.learning.mrilc.payload import (
    BISECTIONS,
    GRID,
    MAX_HZ,
    PayloadRefused,
    payload_from_modes,
)

#: the model's modes at no payload (Hz) and the mass that halves each one's stiffness-to-inertia ratio (kg)
F0 = (11.7, 15.5, 26.1)
M0 = (4.0, 2.5, 10.0)


def modes(mass: float) -> list[float]:
    """The three-mode model's modes at ``mass`` kg, Hz (lowest first)."""
    return sorted(f / math.sqrt(1.0 + mass / m) for f, m in zip(F0, M0, strict=True))


class Counting:
    """The model, counting its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, mass: float) -> list[float]:
        self.calls += 1
        return modes(mass)


@pytest.mark.parametrize("mass", [0.3, 2.0, 4.5, 6.0, 9.7])
def test_known_masses_round_trip_from_all_their_modes(mass):
    measured = modes(mass)
    for k in range(3):  # each mode rated in turn, the others in support
        est = payload_from_modes([measured[k], *measured[:k], *measured[k + 1:]], modes)
        assert est.mass == pytest.approx(mass, abs=1e-6) and est.branch == k and est.support == 2
        assert est.model_hz == pytest.approx(measured[k], rel=1e-9) and f"{mass:.3g} kg" in est.describe()


def test_the_third_mode_alone_is_not_ambiguous_and_round_trips():
    est = payload_from_modes([modes(4.5)[2]], modes)
    assert est.mass == pytest.approx(4.5, abs=1e-6) and est.branch == 2 and est.support == 0 and est.others == ()


def test_a_mode_two_branches_give_is_ambiguous_alone_and_resolved_by_the_other_modes():
    low = modes(4.5)[0]
    with pytest.raises(PayloadRefused, match=r"ambiguous: 4.5 kg \(mode 1.* or .* kg \(mode 2") as err:
        payload_from_modes([low], modes)
    assert isinstance(err.value, MrilcError) and "\n" not in str(err.value)
    est = payload_from_modes([low, modes(4.5)[1]], modes)
    assert est.mass == pytest.approx(4.5, abs=1e-6) and est.branch == 0 and len(est.others) == 1
    assert est.others[0] > 6.0  # the second branch's mass, not taken
    # a mode the model does not have (a spurious fit) supports nothing: still ambiguous
    with pytest.raises(PayloadRefused, match="ambiguous"):
        payload_from_modes([low, 3.3], modes)


def test_a_mode_no_mass_in_the_range_gives_is_refused_with_the_range():
    with pytest.raises(PayloadRefused, match=r"no payload in \[0, 10\] kg gives a model mode of 30 Hz.*span"):
        payload_from_modes([30.0], modes)
    heavy = modes(15.0)[2]  # outside the default range, inside a wider one
    with pytest.raises(PayloadRefused, match="no payload in"):
        payload_from_modes([heavy], modes)
    assert payload_from_modes([heavy], modes, mass_range=(0.0, 20.0)).mass == pytest.approx(15.0, abs=1e-6)


@pytest.mark.parametrize("bad", [math.nan, -8.5, 0.0, math.inf, 1e9, "x", None])
def test_a_bad_mode_is_refused_before_the_model_is_asked(bad):
    model = Counting()
    with pytest.raises(PayloadRefused, match=r"is not a finite frequency in \(0, 10000\] Hz"):
        payload_from_modes([bad], model)
    assert model.calls == 0 and MAX_HZ == 1e4


def test_bad_other_modes_are_ignored_and_no_mode_is_refused():
    m = modes(4.5)
    est = payload_from_modes([m[0], math.nan, -1.0, 1e9, m[1]], modes)
    assert est.mass == pytest.approx(4.5, abs=1e-6) and est.support == 1
    with pytest.raises(PayloadRefused, match="no measured mode"):
        payload_from_modes([], modes)


@pytest.mark.parametrize("rng", [(-1.0, 10.0), (5.0, 5.0), (0.0, math.nan), (3.0, 1.0)])
def test_a_bad_range_is_refused(rng):
    with pytest.raises(PayloadRefused, match="mass range"):
        payload_from_modes([9.0], modes, mass_range=rng)


def test_a_failing_or_empty_model_is_refused_with_its_reason():
    def broken(mass: float) -> list[float]:
        raise ValueError("payload mass out of range")

    with pytest.raises(PayloadRefused, match="the model's modes at 0 kg failed: payload mass out of range"):
        payload_from_modes([9.0], broken)
    with pytest.raises(PayloadRefused, match="no mode at 0 kg"):
        payload_from_modes([9.0], lambda m: [math.nan, -1.0])


def test_the_work_is_bounded():
    model = Counting()
    m = modes(4.5)
    payload_from_modes(list(m), model)
    crossings = 3
    assert model.calls <= GRID + crossings * (BISECTIONS + 1) + crossings
