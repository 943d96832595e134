"""The parameters of the learner node's MRILC per move (``mode: mrilc_moves``, :mod:`.learner_moves_mrilc`): one
typed declaration, from which the node declares and reads them and the reference page is generated."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from shaper_nodes.ros.parameters import Spec, param, table

from .learner_list import TopicParams

__all__ = ["PARAMETERS", "MrilcMovesGroup", "MrilcMovesParams"]


@dataclass(frozen=True)
class MrilcMovesGroup:
    """mrilc_moves.*: the learner's and the correction's settings."""

    operator: str = param("", "The lifted operator's provider, 'module:function' called as f(goal_pose, count,"
                          " samples, first, spacing, period) -> G ((samples x 3) x (count x joints), m/s^2 per rad);"
                          " the simulated arm's: 'sim_plant_node.arm.lifted:arm_operator'. Required.", read_only=True)
    controller: str = param("/joint_trajectory_controller/follow_joint_trajectory", "The controller's"
                            " FollowJointTrajectory action the corrected goals go to.", read_only=True)
    action_timeout: float = param(30.0, "How long a goal waits for the controller's action server and its"
                                  " answer, s.", (0.1, 600.0), read_only=True)
    match_timeout: float = param(2.0, "How long a goal of a move not known yet waits for its START on the cycle"
                                 " events, s (a known move's goal is matched at once by its first and last points).",
                                 (0.0, 60.0), read_only=True)
    gain: float = param(0.5, "Learning gain gamma.", (1e-6, 1.0), read_only=True)
    regularisation: float = param(1e-3, "rho relative to the mean of diag(G^T G).", (1e-12, 1e6), read_only=True)
    patience: int = param(2, "Divergence guard: cycles in a row above growth x the best cost before falling back.",
                          (1, 1000), read_only=True)
    growth: float = param(1.2, "Divergence guard: cost ratio to the best that counts as growing.", (1.0001, 100.0),
                          read_only=True)
    noise_floor: float = param(0.0, "Divergence guard: costs below this never count as growing, m/s^2.",
                               (0.0, 1e3), read_only=True)
    max_fallbacks: int = param(3, "Fallbacks to the best coefficients before holding them.", (1, 1000),
                               read_only=True)
    spacing: float = param(0.04, "s between the correction's B-spline knots.", (0.004, 1.0), read_only=True)
    tail: float = param(0.4, "The correction acts in the last tail s of the shaped motion.", (0.02, 10.0),
                        read_only=True)
    fine_spacing: float = param(0.004, "s between the knots of the second family of B-splines (the position"
                                " loop's transient).", (0.001, 1.0), read_only=True)
    fine_tail: float = param(0.048, "The second family acts in the last fine_tail s of the shaped motion (0: no"
                             " second family).", (0.0, 10.0), read_only=True)
    position_min: tuple[float, ...] = param([-2 * math.pi], "Lowest joint positions, rad (one per joint, or one"
                                            " for all).", read_only=True)
    position_max: tuple[float, ...] = param([2 * math.pi], "Highest joint positions, rad.", read_only=True)
    velocity: tuple[float, ...] = param([math.pi], "Largest joint speeds, rad/s.", read_only=True)
    acceleration: tuple[float, ...] = param([15.0], "Largest joint accelerations, rad/s^2.", read_only=True)
    drift_status: str = param("identifier: drift", "The /diagnostics status whose WARN (a drift warning: a payload"
                              " change) drops every move's correction and restarts its learner ('' = none).",
                              read_only=True)
    payload_mass: float = param(0.0, "The payload the robot is told, kg (0: not told, the operator provider's own):"
                                " when set, the provider is called with payload= it; a change takes effect when each"
                                " move's operator is next built (a drift warning's relearn, a restart). Set it when"
                                " the robot's payload changes (payload_from_drift sets it too).", (0.0, 1000.0))
    payload_from_drift: bool = param(True, "At a drift warning's relearn, work the payload out from the mode the"
                                     " warning carries (with modes set) and set payload_mass to it; refused (no mass"
                                     " in payload_range matches, ambiguous), payload_mass is kept. Default on: on the"
                                     " old payload's operator the relearn does not converge.", read_only=True)
    modes: str = param("", "The model's modes, 'module:function' called as f(goal_pose, payload) -> Hz; the"
                       " simulated arm's: 'sim_plant_node.arm.lifted:arm_modes' ('' = no payload from the drift).",
                       read_only=True)
    payload_range: tuple[float, ...] = param([0.0, 10.0], "The payloads searched for the drift's mode, [low, high]"
                                             " kg (default 0 to twice a UR5e's rated 5 kg).", read_only=True)


@dataclass(frozen=True)
class MrilcMovesParams:
    """The MRILC-per-move mode's parameters."""

    mrilc_moves: MrilcMovesGroup = field(default_factory=MrilcMovesGroup)
    topics: TopicParams = field(default_factory=TopicParams)


#: the MRILC-per-move mode's parameters (derived from MrilcMovesParams)
PARAMETERS: tuple[Spec, ...] = table(MrilcMovesParams)
