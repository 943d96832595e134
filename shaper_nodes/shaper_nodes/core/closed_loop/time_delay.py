"""Closed-loop input shaping with a time-delay feedback controller (seed 001, Staehlin and Singh).

The time-delay filter (PPUSMD, "proportional plus user selected multiple delay")

    G_FF(s) = A0 + A1 e^{-sT} + A2 e^{-2sT},
    A0 = A2 = 1 / (2 (1 - cos(w_A T))),   A1 = -2 cos(w_A T) / (2 (1 - cos(w_A T)))   (eqs. 9-11)

cancels the undamped mode w_A of the assumed plant G_PA = w_A^2 / (s^2 + w_A^2) for any delay
T (with cos(w_A T) != 1); its gains sum to 1. The feedback controller of the IMC structure

    G_C = G_FF / (1 - G_FF G_PA)                                                      (eq. 3)

gives, on the real plant G_PR = w_R^2 / (s^2 + w_R^2), the loop whose characteristic
quasi-polynomial is (eq. 18, with G = G_FF(s))

    F(s) = s^2 (s^2 + w_A^2 (1 - G)) + w_R^2 (w_A^2 + s^2 (1 + G)).

Its imaginary-axis crossings are at s = j k pi / T with w_R(k) of eq. (15) and at s = j w_A
with w_R = w_A (eqs. 16-17); the loop is stable for w_A <= w_R <= min(w_R(k) > w_A) (eq. 27;
at w_R = w_A exactly the plant's undamped poles are cancelled by the controller's zeros, so the
loop is only marginally stable: see docs/design/closed_loop.md). For a plant w_R and a delay T, eqs.
(28)-(30) give the range of w_A to choose.

The independent check (:func:`sampled_spectral_radius`) builds the sampled-data loop (exact
zero-order-hold discretisation of plant and internal model, delays of whole samples) and takes
the spectral radius of its transition matrix; it uses none of the analysis above.

Performance (beyond the paper, which only reads overshoots off its figures): the exact step response
(:func:`exact_step_response`, method of steps) gives overshoot, peak time and settling time;
:func:`step_performance` puts them beside both stability checks for one w_R, and
:func:`overshoot_interval` gives the w_R of the stable interval where the exact overshoot meets a limit.
"""

from __future__ import annotations

from .delay_stability import (
    AssumedRange,
    Crossing,
    StableInterval,
    TimeDelayError,
    assumed_frequency_range,
    change_points,
    characteristic,
    controller_response,
    g_ff,
    growth_rate,
    ppusmd_gains,
    sampled_loop_matrix,
    sampled_spectral_radius,
    stable_interval,
    upper_bound_curve,
)
from .delay_step import (
    DEFAULT_BAND,
    MAX_ROUNDING_ERROR,
    OvershootInterval,
    OvershootSegment,
    StepPerformance,
    StepResponse,
    exact_step_response,
    overshoot_interval,
    step_performance,
    step_response_with_horizon,
)

__all__ = ["DEFAULT_BAND", "MAX_ROUNDING_ERROR", "AssumedRange", "Crossing", "OvershootInterval", "OvershootSegment",
           "StableInterval", "StepPerformance", "StepResponse", "TimeDelayError", "assumed_frequency_range",
           "change_points", "characteristic", "controller_response", "exact_step_response", "g_ff", "growth_rate",
           "overshoot_interval", "ppusmd_gains", "sampled_loop_matrix", "sampled_spectral_radius", "stable_interval",
           "step_performance", "step_response_with_horizon", "upper_bound_curve"]
