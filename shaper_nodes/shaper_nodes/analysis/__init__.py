"""Offline analysis of recordings (rosbag2 folders or bare MCAP files), free of rclpy.

- :mod:`.reading`: open a bag with rosbags, or recover what a truncated or corrupt MCAP holds
  with the ``mcap`` library's record parsers; deserialise with rosbags' typestores.
- :mod:`.streams`: find the accelerometer, joint-state, command, cycle-event and shaper topics
  by type and extract them into arrays.
- :mod:`.segment`: cycles from the cycle events, or from the commands' motion when there are none.
- :mod:`.analyze`: per-cycle residual vibration and settling, spectrum, modes, recommended shaper,
  learner replays (a registry: LIST now, MRILC to be added).
- :mod:`.report`: terminal table, Markdown, CSV, JSON and PNG plots.

The CLI is :mod:`shaper_nodes.bag_analysis_cli` (``analyze_bag``); see docs/bag_analysis.md.
"""
