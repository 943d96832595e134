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
plant
    :class:`ArmPlant`, the arm as a :class:`~sim_plant_node.models.base.Plant` of the sim plant node.
task, metrics
    The pick-and-place cycle, and the residual vibration and path deviation of a move.
offline
    The arm and its controller emulation (:mod:`sim_plant_node.controller`) stepped without ROS.
lifted
    MRILC per move's lifted operator: the flange accelerometer's response to each B-spline coefficient of a
    joint profile correction, the arm linearised at the move's goal pose.
residual_parts, residual_watch
    The residual's two parts (the position loop's transient, the joints' vibration) from the arm's state at
    the commanded end, and the watch that finds that state move by move (what the sim plant node reports).
"""

__all__ = ["description", "dynamics", "lifted", "metrics", "modal", "offline", "plant", "residual_parts",
           "residual_watch", "task"]
