"""ROS-free core of the vibration-suppression suite.

Nothing in this package imports rclpy or message types: nodes convert messages to numpy
arrays at the edge and call these functions and classes.

Modules
-------
shapers
    Impulse sequences (ZV, ZVD, ZV-D^n, MZV, EI, two- and three-hump EI, SI, custom) behind a
    registry of named designs.
vibration
    The percentage vibration V(omega, zeta) of an impulse sequence, sensitivity curves, and
    residual-vibration metrics of measured cycles.
fir
    Discretisation of an impulse sequence to a causal FIR at the command rate, and the
    streaming multi-joint FIR with bumpless coefficient changes.
trajectory
    Whole-trajectory shaping (resampling, convolution, derivatives) for
    joint_trajectory_controller.
identification
    Vibration modes (frequency, damping, uncertainty) from free decays, and the shaper
    recommendation by worst-case vibration over the uncertainty band.
list_learning, list_session
    The Learning Input Shaping Technique (seed 003), and the bookkeeping the learner node and
    the offline replay share.
cycles
    Per-cycle buffering and the residual-vibration window every component measures alike.
time_delay, qft
    Closed-loop shaping: the time-delay feedback controller's stability analysis (seed 001) and
    QFT model matching with bounds on the Nichols chart (seed 002).
validation
    Checks of incoming data with errors that name the problem.
"""
