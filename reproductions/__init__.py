"""The paper reproductions: the seeds' experiments run through the ROS graph, and the tables they print.

Each module starts the real nodes as separate processes (the sim plant, the shaper and, where the
seed needs them, the learner or the scheduler; :func:`sim_plant_node.clients.conductor.node_session`),
drives them over their public interfaces, and writes a results page under ``docs/results/`` with its
plots under ``docs/results/img/``. The integration tests in ``tests/`` call the same functions with the
tolerances of the papers. Run one from the repository root (``--help`` lists its options; the
logs of the node processes go to ``out/<module>/``):

:mod:`reproductions.mrilc_cases`
    Seed 000, MRILC: the ZVD shaper alone on the nominal and the perturbed plant, then the
    learning curves of the P-type and the robust law. Writes docs/results/mrilc_results.md.
    ``./run exec python -m reproductions.mrilc_cases``
:mod:`reproductions.closed_loop_cases`
    Seeds 001 and 002: the time-delay feedback controller around plants inside and outside its
    stable interval, and ZV with the QFT loops against open-loop ZV and ZVD on the eight corner
    plants. Writes docs/results/closed_loop_results.md; what it measures on the loops' signals is
    :mod:`reproductions.closed_loop_measures`.
    ``./run exec python -m reproductions.closed_loop_cases``
:mod:`reproductions.list_cases`
    Seed 003, LIST: the four cases (LTI, time-varying mass, hardening spring, saturated
    actuator), one learning iteration a cycle. Writes docs/results/list_results.md.
    ``./run exec python -m reproductions.list_cases``
:mod:`reproductions.scheduler_cases`
    Seed 004: the two-mass system through five velocity steps with a fixed ZV, the two-set
    switch and the TS fuzzy scheduler. Writes docs/results/scheduler_results.md; its rule bases (ROS-free)
    are :mod:`reproductions.scheduler_rules`.
    ``./run exec python -m reproductions.scheduler_cases``
:mod:`reproductions.bag_results`
    The bag analysis on the demo's recording and on a recording by another writer, whole and
    cut short. Writes docs/results/bag_analysis_results.md.
    ``./run exec python -m reproductions.bag_results``

:mod:`reproductions.common` holds what they share (the ``--docs`` option, the logs folder, the
driver of the learner runs).

The arm's reproductions run the six-axis arm and its controller emulation without ROS
(:mod:`sim_plant_node.arm.offline`), deterministic, each writing its page under ``docs/results/``:
:mod:`reproductions.arm_modes` (the lowest mode over the workspace), :mod:`reproductions.arm_calibration`
(the calibration against modal analysis, and its schedule), :mod:`reproductions.arm_learning` (learning per
move: LIST over the schedule and alone, speed-up, payload change), :mod:`reproductions.arm_mrilc` and
:mod:`reproductions.arm_mrilc_payload` (MRILC per move, and after a payload change),
:mod:`reproductions.arm_physics` (the residual's servo and vibration parts; the measure in
:mod:`reproductions.residual_split`), :mod:`reproductions.arm_speed_estimate` (the speed learner's
accelerometer test against the flange), :mod:`reproductions.arm_speed_list` (the page of
``scheduled_list_speedup``). :mod:`reproductions.bag_noise` is the bag analysis with measured joint states
(noise and encoder steps).
"""
