"""Learning from repeated cycles, free of ROS.

Subpackages and modules
-----------------------
goal_shaping
    Which shaper each cycle's goal ran with (the shaper node's ``~/shaped_goals``), matched to the cycle whose
    START named its goal, and why a per-move learner may not learn from a cycle whose goal fell back.
list
    The Learning Input Shaping Technique (seed 003): a two-impulse shaper tuned cycle by cycle
    from the residual vibration (parameters, measurement, the learner, the session the node and
    the offline replay share).
mrilc
    Model-Reference Iterative Learning Control (seed 000): the reference model, the convergence
    check and learning laws, the learner with its divergence guard, the session, and the
    parameters (names, defaults, ranges) the node and replays share.
moves
    Per-move learned state: a move's identity from its start and goal poses (or a name), one entry
    per move (LIST state, correction, measures, speed factor), saved atomically as one versioned
    document and loaded back entry by entry, each checked.
samples
    Compact stamped sample buffers that give memory back (both learners' cycles), the defaults
    of the cycle duration limit and the accelerometer's range, and the check of samples against
    a sensor's range (saturated or implausible samples; the identifier node uses it too).
speed
    Learning to move faster: a per-move time-scaling factor raised while the move stays within its
    tolerance and the joint limits, lowered at once on a violation, then bisected.
speed_limits
    The rules a time-scaled move is held to (the speed learner's and its node's): the profile run faster, the
    joint limits' ceiling and breaches, measured peaks against limits, a flange tolerance as an accelerometer level.
speed_peaks
    A move's joint torques and speeds predicted at a higher factor from those measured at lower
    ones (torque a + b s^2, speed b s), and the largest factor whose predictions stay within the
    limits less a margin: the speed learner's hold before a raise.
state_file
    Atomic JSON state files with a version, checked fully when read, and the start-up load that
    never fails: a file that cannot be used is reported, moved aside if it can be, and ignored.
"""

__all__ = ["goal_shaping", "list", "moves", "mrilc", "samples", "speed", "speed_limits", "speed_peaks", "state_file"]
