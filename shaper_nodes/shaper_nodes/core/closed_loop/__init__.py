"""Closed-loop input shaping analysis, free of ROS.

Modules
-------
time_delay
    The time-delay feedback controller of seed 001 (PPUSMD gains, the IMC controller): the
    interval of real plant frequencies for which the loop is stable, the assumed frequency to
    choose, the exact step response (overshoot, settling), and a sampled-data check; the equations, and every
    name of the two modules below handed on.
delay_stability
    The loop's stability: the gains and the controller, the crossings, the stable interval, the assumed
    frequencies, the sampled-data check.
delay_step
    The exact step response (method of steps), its horizon, the performance, the overshoot interval.
qft
    QFT model matching of seed 002: the uncertain m-c-k plant set, the controller of eq. (10),
    |M - Y/R| per corner plant and frequency, templates and bounds on the Nichols chart.
"""

from .qft import corners, nominal, plant_tf
from .time_delay import exact_step_response, ppusmd_gains

__all__ = ["corners", "exact_step_response", "nominal", "plant_tf", "ppusmd_gains"]
