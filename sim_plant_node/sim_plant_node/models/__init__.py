"""The simulated models, free of ROS, behind one interface.

Modules
-------
base
    :class:`~.base.Plant`, the interface every model implements (the arm's :class:`ArmPlant` too):
    step, sensors, state, live changes; :class:`~.base.PlantBase`, the defaults of a 1-D model.
plants
    The m-c-k flexible joint and the four LIST plants (seed 003).
list_scalar
    The LIST plants' period for one joint in Python floats, bit for bit the arrays' arithmetic (faster).
cycle_task
    The repeated point-to-point task of the 1-D plants (:class:`~.cycle_task.CycleTask`): the moves, the
    dwells and the cycle events at the samples they happen.
pid_loop
    The m-c-k joint in a continuous feedback loop with a feedforward effort (seed 000).
loops
    The closed loops of seeds 001 (time-delay feedback) and 002 (QFT).
two_mass
    Seed 004's two-mass system and its staircase task.

Models (the sim plant node's parameter ``plant.model``; docs/list_plants.md)
--------------------------------------------------------------------------
mck
    Base-driven m-c-k flexible joint (spring and damper between base and tip), exact.
list_linear, list_time_varying, list_hardening, list_saturation
    The four plants of the LIST simulations (seed 003): damper to ground; mass that doubles
    over the first second of every cycle; cubic hardening spring ``plant.stiffness_cubic``;
    P loop ``plant.gain`` with actuator force limit ``plant.force_limit``. The time-varying
    mass follows the time since the current cycle's START event.
mck_pid
    The mck plant inside the loop of a continuous feedback controller C(s)
    (``controller.numerator``/``denominator``, default seed 000's PID), with a feedforward
    effort u2 (seed 000, MRILC): /joint_states carries the output y and the total effort u,
    ``~/reference`` the applied (shaped) reference. See :mod:`.pid_loop`.
arm
    The six-axis elastic-joint arm (UR5e figures, Pinocchio; docs/arm.md), chosen at start-up,
    behind an emulation of joint_trajectory_controller: FollowJointTrajectory on
    ``topics.jtc_action``, JointTrajectory on ``topics.jtc_topic`` (:mod:`sim_plant_node.controller`),
    and the forward command topic while a task runs. /joint_states carries the motor-side
    positions, velocities and torques, ``~/tip_state`` the link angles, the IMU the flange's
    specific force (gravity included) and angular rate at every physics step (rate x
    ``arm.substeps``). In lockstep the arm steps while the controller executes a trajectory;
    at rest it publishes its last joint state again every 0.1 s of wall time (simulated time
    stands still), as a robot's joint_state_broadcaster keeps publishing. The payload at the
    flange (``arm.payload_mass``, ``arm.payload_offset``) changes live (``ros2 param set``): the
"""

__all__ = ["base", "cycle_task", "list_scalar", "loops", "pid_loop", "plants", "two_mass"]
