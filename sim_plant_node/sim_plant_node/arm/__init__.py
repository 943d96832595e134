"""The six-axis arm of the simulator, free of ROS.

Modules
-------
description
    The published figures of the arm (UR5e DH parameters, masses, centres of mass, torque
    limits), the modelling choices (inertias, payload, joint stiffness and damping, motors) and
    the URDF written from them.
dynamics
    :class:`ArmModel` (Pinocchio on that URDF) and :class:`ElasticArm`, the elastic-joint arm
    under its motor-side position loop, integrated by the trapezoidal rule; the flange IMU.
modal
    Modal analysis of the linearised arm at any pose (frequencies, damping ratios, mode
    shapes), and the map of the lowest mode over the workspace.
controller
    The emulation of joint_trajectory_controller: goal validation with its error codes,
    interpolation, tolerances, preemption, sampled at its update rate.
"""
