"""The vibration-suppression suite's Python package: input shaping that learns, for ROS 2.

Layers, each importing only from those above it in this list:

core/
    The science, free of ROS: shaping, identification, learning (LIST, MRILC), scheduling (Takagi-
    Sugeno), closed-loop analysis, and the checks and cycle bookkeeping they share.
recordings/
    Recordings (rosbag2 folders, MCAP), free of ROS: the bounded reader with damage recovery, the
    writer, the type store, CDR and the recorder's heartbeat.
ros/
    The glue between messages and the core, written once: QoS profiles, conversions, diagnostics,
    parameter tables, the service clients with bounded waits, the node ``main``, and starting
    installed executables.
nodes/, cli/, analysis/
    Thin nodes (one concept each), the command-line tools, and the offline analysis of recordings.

README.md's "Where is the code" table names the one module that holds each algorithm and node.
"""
