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
samples
    Compact stamped sample buffers that give memory back (both learners' cycles), the defaults
    of the cycle duration limit and the accelerometer's range, and the check of samples against
    a sensor's range (saturated or implausible samples; the identifier node uses it too).
state_file
    Atomic JSON state files with a version, checked fully when read, and the start-up load that
    never fails: a file that cannot be used is reported, moved aside if it can be, and ignored.
"""

__all__ = ["list", "mrilc", "samples", "state_file"]
