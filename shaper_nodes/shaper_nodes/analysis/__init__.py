"""Offline analysis of recordings (rosbag2 folders or bare MCAP files), free of rclpy.

Recordings are opened and read through :mod:`shaper_nodes.recordings` (bounded, damaged files
recovered); nothing here imports ``shaper_nodes.ros`` or ``shaper_nodes.nodes``.

- :mod:`.streams`: find the accelerometer, joint-state, command, cycle-event and shaper topics
  by type and extract them into arrays (:mod:`.signals`: the arrays; :mod:`.collect`: the rows read
  from the messages, turned into them).
- :mod:`.segment`: cycles from the cycle events, or from the motion of the commands or joint states
  when there are none, with thresholds from the positions' measured noise.
- :mod:`.groups`: cycles that see different modes (several plants, payloads or poses), grouped.
- :mod:`.analyze`: per-cycle residual vibration and settling, spectrum, modes, recommended shaper,
  and the learner replays the options ask for; its steps in :mod:`.cycle_rows` (the cycles, their rest
  and figures) and :mod:`.verdict` (the modes of each group, whose are given, the recommendation, the
  headline).
- :mod:`.replay`: what the learners (LIST, MRILC) would have done over a recording, fed as the live
  nodes are fed; the registry ``LEARNER_REPLAYS``.
- :mod:`.report`: terminal table, Markdown, CSV, JSON; :mod:`.report_figures`: the PNG plots.
- :mod:`.fleet`, :mod:`.fleet_drift`, :mod:`.fleet_report`: a fleet's recordings analysed on Dask and cached
  by content, each robot's modes against its baseline (drift alerts, retunes), the fleet report.
- :mod:`.calibration`: a calibration's results from its recording (the pose map, the scheduler's rule base),
  identified in :mod:`.calibration_pool` on :mod:`.worker_pool`'s processes; :mod:`.calibration_outputs`
  makes report.json and the YAML files' texts, :mod:`.calibration_report` writes them with report.md and its
  figures.
- :mod:`.outcome` (:class:`~.outcome.Analysis`, what the analysis found), :mod:`.text` (numbers in the
  reports' texts), :mod:`.options` (the analysis' options), :mod:`.synthetic` (recordings as a robot's own
  recorder writes them, for tests and benchmarks).

The CLIs are :mod:`shaper_nodes.cli.analyze_bag` (``analyze_bag``) and :mod:`shaper_nodes.cli.list_replay`
(``list_replay``); see docs/guide/analysis.md.
"""
