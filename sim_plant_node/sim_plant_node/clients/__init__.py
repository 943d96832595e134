"""What drives the sim plant node from outside, as a robot cell's program or a test would.

Modules
-------
conductor
    Start nodes in their own processes, set parameters, run cycles and collect their results; the
    helpers the tests, the demos and the reproductions share.
demo
    The demo (``demo``, ``python -m sim_plant_node.demo``): the joint story (shapers against a mode off
    its design, recorded) or the arm's.
arm_demo
    The arm's story: the pick-and-place cycle through joint_trajectory_controller, unshaped and shaped;
    its client and measures (:mod:`.arm_client`), its cases and the calibration step (:mod:`.arm_cases`),
    its tables and plot (:mod:`.arm_report`).
"""

__all__ = ["arm_demo", "conductor", "demo"]
