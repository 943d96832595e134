"""ROS-free core of the vibration-suppression suite.

Nothing in this package imports rclpy or message types: nodes convert messages to numpy arrays
at the edge (``shaper_nodes.ros.conversions``) and call these functions and classes. Each
subpackage's ``__init__`` lists its modules and exports its API.

Subpackages and modules
-----------------------
shaping
    Impulse sequences behind a registry of named designs (ZV, ZVD, ZV-D^n, MZV, EI, two- and
    three-hump EI, SI, custom), their percentage vibration, their causal FIR at the command rate
    with bumpless switching, whole-trajectory shaping, and the shaper node's update policy.
identification
    Vibration modes (frequency, damping, uncertainty) from free decays, and the shaper
    recommendation by worst-case vibration over the uncertainty band.
learning
    The Learning Input Shaping Technique (seed 003, ``learning.list``), Model-Reference Iterative
    Learning Control (seed 000, ``learning.mrilc``), and their state files.
scheduling
    Takagi-Sugeno fuzzy interpolation of linear models (seed 004), the scheduler's learner
    corrections per region, and its rate limit.
closed_loop
    Closed-loop shaping analysis: the time-delay feedback controller (seed 001) and QFT model
    matching (seed 002).
cycles
    Per-cycle buffering and the residual-vibration window every component measures alike; the
    cycle event codes (those of shaper_msgs/CycleEvent).
cycle_records
    A finished cycle's residual-vibration record checked before it is identified from (gaps, too few
    samples, a failed or saturated sensor).
checks
    The one home of the number and array checks, with errors that name the problem.
calibration
    Calibration of a robot's workspace: the plan (poses, excitations, limits) and the pose map it measures.
lifetime
    A child process that ends with its parent (the parent-death signal).
memory
    Freed memory given back to the system after something large was dropped (glibc ``malloc_trim``).
files
    Files written whole (:func:`~shaper_nodes.core.files.write_atomic`): the old one or the new one.
stamps
    The one conversion of a ``sec``/``nanosec`` pair (a stamp, a duration) to seconds.
closed_pipe
    A command whose reader went away (``... | head -1``) ends quietly with status 141.
lockstep
    The sim plant's lockstep exchange with the shaper: ask numbering and labels, block layouts,
    late answers, the rows of a received block.
rate
    How a streamed input arrives against its nominal rate: rate, gaps, bursts, drops and lag.
security
    Who may talk to whom on the DDS domain: the SROS2 access policy table, ROS-to-DDS name
    mangling, and the DDS-Security governance and permissions documents (no cryptography).
lazy
    Heavy modules (python-control, scipy.signal) imported on first use, so that a process that
    never needs them starts without them.
"""

__all__ = ["calibration", "checks", "closed_loop", "closed_pipe", "cycle_records", "cycles", "files", "identification",
           "lazy", "learning", "lifetime", "lockstep", "memory", "rate", "scheduling", "security", "shaping", "stamps"]
