"""The suite's nodes: thin adapters from messages to the core, one concept each.

Modules
-------
shaper
    ``shaper_node``: the causal real-time FIR per joint between a motion source and a controller;
    whole trajectories; the update policy. With :mod:`.trajectory_action`, the
    FollowJointTrajectory proxy in front of joint_trajectory_controller.
identifier
    ``identifier``: modes from the last cycles' residual vibration, and the recommended shaper; its drift
    watch in :mod:`.identifier_watch`.
learner
    ``learner``: the dispatcher over the LIST (:mod:`.learner_list`) and MRILC
    (:mod:`.learner_mrilc`) adapters, with what they share (state file, END wait, reports).
scheduler
    ``scheduler``: the shaper follows the pose by Takagi-Sugeno interpolation.
calibrate
    ``calibrate``: the modes over the arm's workspace and the scheduler's rule base; its ROS side in
    :mod:`.calibrator`.
recorder, bag_play
    Recording to and playing from rosbag2 MCAP folders on machines without rosbag2.
"""
