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
arm_split, arm_speed, arm_payload
    The arm demo's servo/vibration split per move (the corrected goal over DDS), its ``scheduled_speedup``
    case (the learner's speed-up per move) and its ``payload`` case (the payload changed, the drift watch).
"""

__all__ = ["arm_cases", "arm_client", "arm_demo", "arm_payload", "arm_report", "arm_speed", "arm_split", "conductor",
           "demo"]
