"""The multi-hump EI solve's closed-form Jacobian (``ei._hump_jacobian``) against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from shaper_nodes.core.shaping import ei


@pytest.mark.parametrize("humps", [1, 2, 3])
@pytest.mark.parametrize("zeta", [0.0, 0.1, 0.3])
def test_the_jacobian_is_the_derivative_of_the_equations(humps, zeta):
    """Around the undamped closed form (perturbed, so no frequency sits on another), every entry agrees with
    central differences to 1e-6 of the largest."""
    v = 0.05
    amps, hump, zero = ei._undamped_hump_ei(humps, v)
    n = humps + 2
    x0 = np.concatenate([amps[:-1], 0.5 * np.arange(1, n), [h for h in hump if h != 1.0],
                         [z for z in zero if z != 1.0]])
    rng = np.random.default_rng(humps * 10 + int(zeta * 100))
    for _ in range(5):
        x = x0 + 0.02 * rng.standard_normal(x0.size)
        numeric = approx_derivative(ei._hump_equations, x, method="3-point", args=(humps, v, zeta))
        exact = ei._hump_jacobian(x, humps, v, zeta)
        assert exact.shape == numeric.shape == (x.size, x.size)
        assert np.max(np.abs(exact - numeric)) <= 1e-6 * max(1.0, float(np.max(np.abs(numeric))))
