"""Benchmarks of the shaper suite: figures and ratios measured in one run, never pass/fail.

Run with ``./run bench`` (``python -m benchmarks`` in the suite's environment; ``--help`` lists
the options). Every figure is printed next to a baseline measured in the same run, because the
machines it runs on are small and noisy. The run ends with one summary table (figure, value,
baseline of the same run, ratio, goal) that ``--json PATH`` writes too; figures and goals are in
``docs/results/benchmarks.md``. The run itself is :mod:`benchmarks.__main__` (the options, the order, the report),
the latency targets as it runs them and their tables :mod:`benchmarks.latency_suite`, the summary table and its goals
:mod:`benchmarks.summary`:

* :mod:`benchmarks.latency`: round-trip latency (driver -> node -> driver) and CPU share of the
  shaper node at 1 kHz with 7 joints, against a bare echo node (:mod:`benchmarks.echo_node`) and the floor
  (the same echo's raw bytes on the shaper's take loop, ``echo_node --take``): the interleaved measurement;
  its parts are the targets (:mod:`benchmarks.latency_targets`), the driver node
  (:mod:`benchmarks.latency_driver`), the replies matched to the sends and their figures
  (:mod:`benchmarks.latency_replies`), the CPU accounting (:mod:`benchmarks.proc_cpu`) and the busy-loop
  load (:mod:`benchmarks.cpu_hog`).
* :mod:`benchmarks.callback_parts` (run on its own, not by ``./run bench``): where a streamed message's
  time goes inside the echo and shaper nodes (wake-up, callback and its parts), timed in their processes.
* :mod:`benchmarks.hop_work` (run on its own): the shaper hop's own work per message (the array callback's
  read, rules, FIR and write) in one process, hot; ``--source`` times another checkout's code, for A B A B.
* :mod:`benchmarks.watch_cost` (run on its own): the shaper node's main-thread bookkeeping per message (the
  rate watch over a batch of kept arrivals, the summary) in one process, hot or ``--cold``; ``--source`` likewise.
* :mod:`benchmarks.raw_path` (run on its own): the array hop's conversions in one process, message
  objects against the serialized bytes the shaper node reads and writes (no DDS).
* :mod:`benchmarks.raw_trajectory` (run on its own): the same for the stream topic's JointTrajectory.
* :mod:`benchmarks.arm_readers` (run on its own): the arm's readers' callbacks on message objects against
  serialized bytes, and the sim plant in lockstep with one reader of the demo client's streams (its per-message
  parts in :mod:`benchmarks.arm_reader_calls`).
* :mod:`benchmarks.fir_throughput`: joint-samples per second of the FIR core
  (``StreamingShaper``), sample by sample and in blocks, against ``scipy.signal.lfilter`` (median per
  block or per 100 samples; ``python -m benchmarks.fir_throughput --runs 3`` on its own).
* :mod:`benchmarks.list_update`: one LIST update for a 10 s cycle of 1 kHz 3-axis accelerometer
  data, against ``filtfilt`` + ``hilbert`` on the same data.
* :mod:`benchmarks.scheduler`: one rule-base evaluation plus design against the design alone, and
  the scheduler node's CPU share at 500 Hz joint states against an idle subscriber.
* :mod:`benchmarks.discretization`: the exact discretisation against the split.
* :mod:`benchmarks.arm_lockstep`: simulated seconds per wall second of the six-axis arm (core and
  the sim plant node over DDS) against one Pinocchio ``aba`` call per step.
* :mod:`benchmarks.bag_analysis`: messages per second of the bag analysis on a recording of a
  million messages, against the rosbags reader alone iterating the same bag.
* :mod:`benchmarks.fleet`: 200 short recordings of 10 robots (two drifting) analysed serially, on 1 and
  2 local Dask worker processes, and again from the cache; the robots the drift rule flags.
* :mod:`benchmarks.learner_memory`: the learners' memory (RSS and their sample buffers) over a
  simulated 1-hour LIST cycle at 1 kHz, against a 10 s cycle in the same run, and over 24
  simulated hours of MRILC at 500 Hz, each in a process of its own.
* :mod:`benchmarks.streaming_gap`: the shaper node's streaming path at 1 kHz while the largest
  whole trajectory it accepts is shaped, against streaming alone in the same run; and the
  interpreter stalls a trajectory causes the node's process, per trajectory size.

Run on their own (``python -m benchmarks.NAME``): :mod:`benchmarks.latency_executors` (the shaper's hop with
each ``stream_executor``), :mod:`benchmarks.big_goal` (a huge FollowJointTrajectory goal against the shaper
node), :mod:`benchmarks.mrilc_update` (one MRILC update against a floor), :mod:`benchmarks.plant_step` and
:mod:`benchmarks.arm_step` (a lockstep plant's own cost per step, one joint and the arm),
:mod:`benchmarks.arm_imu_tail` (a burst of reliable Imu samples to its last, message objects against CDR
bytes), :mod:`benchmarks.arm_threads` (per-thread scheduler figures from /proc),
:mod:`benchmarks.profile_node` (cProfile of a node under the latency driver; :mod:`benchmarks._profiled` runs a
program profiled in every thread).
"""
