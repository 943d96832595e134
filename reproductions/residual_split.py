"""The two parts of the arm's residual vibration: the position loop's transient (the servo part) and the joints'
vibration (the vibration part).

The measure has one copy, :mod:`sim_plant_node.arm.residual_parts` (its docstring states what it is and how close
the two parts together come to the simulated residual); the sim plant node reports it for every move of its arm
(:mod:`sim_plant_node.arm.residual_watch`), and the reproductions take it from here
(``python -m reproductions.arm_physics`` prints it for the cycle's moves).
"""

from __future__ import annotations

from sim_plant_node.arm.residual_parts import (
    SERVO_ZETA,
    LinearArm,
    Parts,
    linear_arm,
    linear_cached,
    residual_parts,
    split_response,
)

__all__ = ["SERVO_ZETA", "LinearArm", "Parts", "linear_arm", "linear_cached", "residual_parts", "split_response"]
