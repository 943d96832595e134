"""The command-line tools; each is a console script of the package (``ros2 run shaper_nodes NAME``).

Modules
-------
shaper_design
    ``shaper_design``: list, show, compare and plot the shaper families (no ROS needed).
loop_design
    ``loop_design``: closed-loop shaping design, time-delay feedback (seed 001) and QFT model
    matching (seed 002).
list_replay
    ``list_replay``: the LIST learner replayed over a recorded bag, cycle by cycle.
analyze_bag
    ``analyze_bag``: per-cycle tables, modes and the learners' replays of a recording
    (:mod:`shaper_nodes.analysis`).
keystore
    ``shaper_keystore``: the suite's SROS2 keystore (CA, one enclave per node, signed permissions
    from :mod:`shaper_nodes.core.security`), made with ``openssl``.
analyze_fleet
    ``analyze_fleet``: a fleet's recordings analysed in parallel on Dask (modes over time per robot, drift
    alerts, retunes).
send_goal
    ``send_goal``: one FollowJointTrajectory goal sent and its result printed (for machines without ros2cli);
    its ``--cycle`` marks on /cycle_events in :mod:`.cycle_marks`.
common
    What they share: argument types, the parser that does not exit, text tables and the ``main``
    that turns bad input into exit status 2.
"""
