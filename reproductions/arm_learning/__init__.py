"""Learning on the arm, per move: LIST over the schedule and alone, speed-up, payload change (issue 31).

``python -m reproductions.arm_learning [--cycles N] [--noise S] [--json PATH] [--cases A,B]``
(``./run exec python -m reproductions.arm_learning``) runs the demo's pick-and-place cycle on the
arm and its controller without ROS (:mod:`sim_plant_node.arm.offline`, deterministic: the IMU
noise has a fixed seed) for every case of :data:`CASES`, ``N`` cycles each, and keeps one learned
state per move in a :class:`~shaper_nodes.core.learning.moves.MoveStore` (saved atomically under
``out/arm_learning/``). The schedule is the offline calibration of
:mod:`reproductions.arm_calibration` (config/calibrate.yaml's plan, 0.01 m/s^2 noise), computed
once and cached in ``out/arm_learning/calibration.json`` (keyed by the plan file's hash; the
calibration is deterministic, so the cache only saves its 2-4 minutes).

Cases (a registry: name -> function returning rows; another helper's MRILC case plugs in with
:func:`register`):

- ``unshaped``, ``fixed`` (the calibration's fallback: ZV on the home pose's modes), ``scheduled``;
- ``scheduled_list``: per move, LIST retunes the scheduled shaper's lowest-mode factor (A1, T2),
  starting from the schedule's own values, T2 never longer than the schedule's (no added delay);
  its reference is the first cycle, shaped by the schedule without that factor; the second runs the
  schedule itself, and a later trial worse than the best measured (in residual or in move + settle
  time) stops the learning there: the pair is kept only when it pays;
- ``scheduled_list_factor``: per move, two-impulse factors convolved with the scheduled shaper, each chosen to
  pay before it is tried: a reference cycle (the schedule; then the schedule with the factors kept so far)
  identifies the residual's components (the modes that ring, the position loop's damped poles, the latter also in
  fits with up to :data:`SERVO_EXTRA` more modes; :func:`~shaper_nodes.core.learning.list.payback.components`), and
  :func:`~shaper_nodes.core.learning.list.payback.paying_factor` picks the factor (T2 within :data:`LIST_BAND` of a
  component, partial pairs included) with the least predicted residual among those whose time cost, predicted
  from the shaped command alone (:func:`~shaper_nodes.core.learning.list.payback.time_cost`, between samples), keeps
  the move + settle time within one 2 ms sample of the schedule's; the next cycle tries it, and it is kept only
  when it pays (:func:`~shaper_nodes.core.learning.moves.keep_when_it_pays`); the move stops at the first trial
  that does not pay or when no factor is predicted to pay. A move with no factor kept whose reference finds none
  (or whose factor from one window did not pay) pools its reference windows (up to :data:`POOL_CYCLES`) and looks
  there for the loop's pole (:mod:`~shaper_nodes.core.learning.list.loop_pole`: what noise hides in one window); a
  factor on it is judged by its measured response at that pole (``PayingFactors.judge_at_pole``);
- ``tradeoff`` (one cycle, a side case): what a factor on a mode that rings costs in move + settle time, and
  the factor chosen within larger time budgets (:data:`TRADEOFF_BUDGETS`);
- ``servo_cost`` (one cycle, a side case): what the pair on the loop's strongest damped component takes off the
  servo part and costs in move + settle time, its zero-vibration pair and the pair within one 2 ms sample;
- ``list``: LIST per move with no calibration. A reference cycle (unshaped at first, then with the kept
  factors) identifies the modes that ring; LIST learns a factor on the lowest, started at its ZV and kept
  within :data:`LIST_BAND` of it (so it stays on the mode that rings), over ZV factors on the other
  identified modes. After :data:`FACTOR_CYCLES` trials, or when LIST holds (converged), or at the first trial that
  does not pay (the same rule against the reference cycle, the time against the move's unshaped cycle:
  there is no schedule), the stage is frozen at its best kept trial (or dropped if none paid), and the
  next reference looks for modes still ringing;
- ``rigid``: one cycle unshaped, fixed and scheduled on the arm with its joints 100x stiffer (the
  physics section: what removing the flexibility does);
- ``speedup``: the schedule with a time-scaling factor per move
  (:class:`~shaper_nodes.core.learning.speed.SpeedLearner`),
  raised while the flange settles within 0.05 mm and the joint velocity and torque limits hold;
- ``scheduled_list_speedup`` (opt-in, :data:`OPTIONAL_CASES`: only with ``--cases``): ``scheduled_list_factor``'s
  factors per move, then, once every move's LIST stopped, the speed-up over the schedule and the kept factors, in
  turn as the two learner nodes run; with ``--noise`` judged by the node's accelerometer estimate
  (:func:`node_speed_estimate`); its page: :mod:`reproductions.arm_speed_list`;
- ``payload``: the schedule, the payload changed from 2 to 4.5 kg after the third cycle; a drift
  watch per move (:class:`~shaper_nodes.core.identification.drift.DriftWatch`) on the modes
  identified in each move's residual; on its warning the moves are re-learned from the drift's
  new modes (a ZV on the modes identified in the move's residual).

Each row (the JSON's ``rows``): case, move, cycle, residual_rms (m/s^2, 1 s after the commanded
motion's end), late_rms (the same without the servo's first 0.1 s), peak_mm, settle_s,
move_settle_s (0.05 mm), speed_factor, delay_s, torque_ratio (largest joint torque / its limit),
velocity_ratio, and the residual's servo and vibration parts (servo_rms, vibration_rms, linear_rms: the two
together; :mod:`reproductions.arm_physics`). Writes docs/results/arm_learning.md and its figures; its goals
section states, per case, the issue's goal and the one corrected goal (the servo part by the time the goal allows,
docs/results/arm_learning_goals.md (a)) once each, judged on the moves above the noise floor by the one rule
(:func:`floor_threshold`), and whether each is met.

The package, a module a concern (``python -m reproductions.arm_learning`` runs :mod:`.cli` through ``__main__``):

- :mod:`~reproductions.arm_learning.runs`: the schedule (:func:`calibration`, :func:`modal_calibration`), the
  :class:`Context`, the arm :class:`Cell` that runs one move and measures it, the :func:`row`, the registry
  (:data:`CASES`, :func:`register`);
- :mod:`~reproductions.arm_learning.factors`: what the factor cases share (the residual's components, the bands,
  the impulse sequences' products);
- the cases: :mod:`~reproductions.arm_learning.schedule` (unshaped, fixed, scheduled, rigid, scheduled_list),
  :mod:`~reproductions.arm_learning.paying` (:class:`PayingFactors`, scheduled_list_factor),
  :mod:`~reproductions.arm_learning.costs` (tradeoff, servo_cost), :mod:`~reproductions.arm_learning.list_case`
  (list), :mod:`~reproductions.arm_learning.speed` (speedup, scheduled_list_speedup),
  :mod:`~reproductions.arm_learning.payload_case` (payload); imported below in that order, which is the registry's
  (:data:`CASES`' order is the default ``--cases`` list and the page's order);
- the page: :mod:`~reproductions.arm_learning.goals` (:func:`checks`, :func:`floor_threshold`) and
  :mod:`~reproductions.arm_learning.pages` (:func:`physics`, :func:`markdown`, the figures);
- :mod:`~reproductions.arm_learning.cli`: :func:`main`.
"""

from __future__ import annotations

# the cases register as their modules are imported: this order is the registry's (CASES), not isort's
# isort: off
from reproductions.arm_learning.runs import (CASES, DWELL, HEAVY, IMU_RATE, OUT, PAYLOAD_AT, RATE, UR5E_MAX_VELOCITY,
                                             CaseFn, Cell, Context, Row, Run, calibration, modal_calibration, register,
                                             row)
from reproductions.arm_learning.factors import JOINT_TOLERANCE, LIST_BAND, SERVO_EXTRA
from reproductions.arm_learning.schedule import SIDE_CASES, fixed, rigid, scheduled, scheduled_list, unshaped
from reproductions.arm_learning.paying import POOL_CYCLES, PayingFactors, scheduled_list_factor
from reproductions.arm_learning.costs import TRADEOFF_BUDGETS, servo_cost, tradeoff
from reproductions.arm_learning.list_case import FACTOR_CYCLES, list_alone
from reproductions.arm_learning.speed import (OPTIONAL_CASES, node_speed_estimate, scheduled_list_speedup,
                                              speed_violations, speedup)
from reproductions.arm_learning.payload_case import payload
from reproductions.arm_learning.goals import checks, floor_threshold
from reproductions.arm_learning.pages import decomposition, figures, markdown, physics, sums, table
from reproductions.arm_learning.cli import main
# isort: on

__all__ = ["CASES", "DWELL", "FACTOR_CYCLES", "HEAVY", "IMU_RATE", "JOINT_TOLERANCE", "LIST_BAND", "OPTIONAL_CASES",
           "OUT", "PAYLOAD_AT", "POOL_CYCLES", "RATE", "SERVO_EXTRA", "SIDE_CASES", "TRADEOFF_BUDGETS",
           "UR5E_MAX_VELOCITY", "CaseFn", "Cell", "Context", "PayingFactors", "Row", "Run", "calibration", "checks",
           "decomposition", "figures", "fixed", "floor_threshold", "list_alone", "main", "markdown",
           "modal_calibration", "node_speed_estimate", "payload", "physics", "register", "rigid", "row", "scheduled",
           "scheduled_list", "scheduled_list_factor", "scheduled_list_speedup", "servo_cost", "speed_violations",
           "speedup", "sums", "table", "tradeoff", "unshaped"]
