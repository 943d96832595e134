"""Learning from repeated cycles, free of ROS.

Subpackages and modules
-----------------------
list
    The Learning Input Shaping Technique (seed 003): a two-impulse shaper tuned cycle by cycle
    from the residual vibration (parameters, measurement, the learner, the session the node and
    the offline replay share).
mrilc
    Model-Reference Iterative Learning Control (seed 000): the reference model, the convergence
    check and learning laws, the learner with its divergence guard, the session, and the
    parameters (names, defaults, ranges) the node and replays share.
state_file
    Atomic JSON state files with a version, as both learners save and reload them.
"""

__all__ = ["list", "mrilc", "state_file"]
