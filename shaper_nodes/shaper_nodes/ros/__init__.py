"""The ROS glue of the suite, written once; nodes build on it, the core never imports it.

Modules
-------
qos
    The QoS profiles: ``LATCHED`` (state for late joiners) and ``IMU_QOS`` (the accelerometer).
conversions
    Messages to and from the core's objects and arrays: shapers, stamps and durations,
    trajectories.
diagnostics
    Throttled refusals and summaries on the log and ``/diagnostics``.
graph_watch
    The graph around a node's command path, watched: another node of its name, other publishers,
    wrong types, incompatible QoS, on the log once and on ``/diagnostics``.
graph_rules
    The graph watch's decisions without a graph: the findings, their status, and which hold (logged once).
parameters
    Parameter tables (``Spec``), ``declare_all`` and ``values``: each node declares its
    parameters from one table, derived from its typed parameter class (``param``, ``table``,
    ``declare`` -> ``Live``, ``read``).
parameters_doc
    The parameter reference (docs/reference/parameters.md) rendered from the tables.
shaper_client
    Service calls with bounded waits (``ServiceClient``) and the one client of ``set_shaper``
    (``ShaperClient``): a lost reply is reported or retried, never a hang.
action_client
    ``ResilientActionClient``: an rclpy action client whose goals and results survive a service
    response lost at start-up (recovered from the status topic, or asked again with the same goal id).
goal_feedback
    ``GoalFeedback``: the feedback stamps of chosen goals on a subscription of the caller's own, kept after
    their results arrive (rclpy's client drops them).
pose_shaper
    A whole trajectory shaped for its final pose with the shaper a scheduler's ``~/shaper_at``
    gives (the shaper node's ``action.scheduler``), falling back to the active shaper with a warning.
shaped_goals
    The shaper node's ``~/shaped_goals`` (shaper_msgs/ShapedGoal): what each goal was shaped with, and why.
node_main
    The Jazzy ``main`` of every node.
side_node
    A node's second node on a thread of its own (the shaper's whole trajectories; lean: the
    shaper's streamed inputs, the scheduler's /joint_states).
whole_trajectory
    Whole-trajectory shaping as the shaper node does it, and the same in a worker process on
    serialized messages.
message_types
    Message classes by their ROS type names (the recorder's subscriptions, bag_play's publishers);
    recordings themselves are read and written by ``shaper_nodes.recordings``.
launching
    Installed node executables started as ``ros2 run`` starts them, for tests and tools.
raw_stream
    Streamed inputs on serialized messages (the shaper's array and JointTrajectory inputs, the scheduler's
    joint states): bytes in, the core's rules, bytes out.
take_loop
    A lean node's subscriptions taken on one wait set built once, instead of rclpy's executor.
sim_clock
    ``use_sim_time``'s ``/clock`` taken on a side node's take loop, not on the node's executor (every node of
    the suite, through ``node_main``).
stream_watch
    The shaper node's bookkeeping of its inputs: arrivals through the rate watch, forwarded and refused counts.
lockstep_reader
    A lockstep reader's side on the wire: its acknowledgements to the sim plant, and its lost samples.
cycle_events
    Cycle events with a START the listener missed stood in for by a later event's ``start_stamp``
    (``EventStream``), and the field filled by a publisher (``set_start_stamp``).
"""
