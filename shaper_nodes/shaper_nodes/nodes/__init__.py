"""The suite's nodes: thin adapters from messages to the core, one concept each.

Modules
-------
shaper
    ``shaper_node``: the causal real-time FIR per joint between a motion source and a controller;
    whole trajectories; the update policy. With :mod:`.trajectory_action`, the
    FollowJointTrajectory proxy in front of joint_trajectory_controller (a goal's rules in
    :mod:`.goal_rules`); its parameters in
    :mod:`.shaper_parameters`, its process' interpreter settings in :mod:`.shaper_interpreter`.
identifier
    ``identifier``: modes from the last cycles' residual vibration, and the recommended shaper; its drift
    watch in :mod:`.identifier_watch` (per move against the scheduler's shapers: :mod:`.identifier_moves`),
    its parameters in :mod:`.identifier_parameters`.
learner
    ``learner``: the dispatcher over the LIST (:mod:`.learner_list`) and MRILC
    (:mod:`.learner_mrilc`) adapters, with what they share (state file, END wait, reports;
    :mod:`.learner_base`). Per move: LIST (:mod:`.learner_moves`; the payback mode :mod:`.learner_payback`,
    :mod:`.learner_payback_cycle`, :mod:`.learner_payback_pole`, :mod:`.learner_payback_parameters`), MRILC
    (:mod:`.learner_moves_mrilc`, its payload :mod:`.learner_payload`), the speed-up (:mod:`.learner_speed`,
    :mod:`.learner_speed_parameters`, the efforts watched in :mod:`.learner_efforts`); the drift warning
    watched (:mod:`.learner_drift`) and the goals matched to moves (:mod:`.move_goals`).
scheduler
    ``scheduler``: the shaper follows the pose by Takagi-Sugeno interpolation; its parameters in
    :mod:`.scheduler_parameters`, the per-move corrections in :mod:`.scheduler_moves`, the learner's interface in
    :mod:`.scheduler_learner`, the lockstep poses in :mod:`.scheduler_lockstep`.
calibrate
    ``calibrate``: the modes over the arm's workspace and the scheduler's rule base; its ROS side in
    :mod:`.calibrator`, its parameters in :mod:`.calibrate_parameters`, how a run stops in
    :mod:`.calibrate_stops`.
recorder, bag_play
    Recording to and playing from rosbag2 MCAP folders on machines without rosbag2.
"""
