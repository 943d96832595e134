"""The emulation of joint_trajectory_controller (ros2_controllers, Jazzy) in front of the simulated arm.

Modules
-------
jtc
    The controller, free of ROS: goal validation with its error codes, interpolation, tolerances,
    preemption, sampled at its update rate.
splines
    The trajectory's interpolation by the fields given (positions, velocities, accelerations). Free of ROS.
server
    Its FollowJointTrajectory action server and JointTrajectory topic, owned by the sim plant node.
"""

__all__ = ["jtc", "server", "splines"]
