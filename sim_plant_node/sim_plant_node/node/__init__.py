"""The ``sim_plant`` node (executable ``sim_plant``) and its parts.

Modules
-------
sim_plant
    :class:`SimPlantNode`: publishers, subscriptions, services, the task runner, the stepping in lockstep
    or real time; ``main``.
controller_runs
    The arm's joint_trajectory_controller in the node: made at start-up, stepped in lockstep while it executes
    a trajectory (its timer off while idle or held by a reader), the joint state again at rest.
live_parameters
    Parameters changed while the node runs: checked whole, applied at the next step.
parameters
    The parameter table :data:`PARAMETERS` (declared from here) and the groups the node reads together.
models
    ``plant.model`` to the :class:`~sim_plant_node.models.base.Plant` it names.
sensors
    /joint_states as the encoders report it and the accelerometer (noise, bias, quantisation).
lockstep
    The node's side of the lockstep exchange with the shaper (its asks on the wire, late answers, timeouts;
    the rules are :mod:`shaper_nodes.core.lockstep`'s).
writer_profile
    The Fast DDS times of the plant's writers (a profiles file named before ``rclpy.init``).
feedforward
    The ``~/set_feedforward`` profile: its checks, installed at a cycle's START. Free of ROS.
residual_report
    The arm's residual split per move (:mod:`sim_plant_node.arm.residual_watch`) on ``~/residual_parts``.
"""

__all__ = ["controller_runs", "feedforward", "live_parameters", "lockstep", "models", "parameters", "residual_report",
           "sensors", "sim_plant", "writer_profile"]
