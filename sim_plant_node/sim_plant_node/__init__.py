"""The simulated robot of the suite: the plants of the five papers and a six-axis arm, the node that
runs them over ROS 2, and the clients that drive it. Nothing here is needed on a real robot.

Packages
--------
models
    The 1-D plants of the seeds (m-c-k, the LIST cases, the PID loop, the closed loops of seeds 001
    and 002, the two-mass system of seed 004), the repeated tasks, and :class:`models.base.Plant`, the
    one interface every model (the arm included) implements. Free of ROS.
arm
    The six-axis elastic-joint arm (UR5e figures, Pinocchio): description, dynamics, modes, its task
    and metrics, and :class:`arm.plant.ArmPlant`, the arm as a Plant. Free of ROS.
controller
    The emulation of joint_trajectory_controller in front of the arm (``jtc``, ``splines``, free of
    ROS) and its action server and topic (``server``).
node
    The ``sim_plant`` node: its parameter table, the model chosen by name, the sensors it publishes,
    the feedforward profile, the lockstep exchange with the shaper (rules in
    :mod:`shaper_nodes.core.lockstep`).
clients
    What drives the node from outside: the conductor (start nodes, run cycles, collect results), the
    demo (``demo``, ``python -m sim_plant_node.demo``) and the arm's demo.

Modules
-------
demo
    ``python -m sim_plant_node.demo``: the demo, which lives in :mod:`.clients.demo`.
"""

__all__ = ["arm", "clients", "controller", "demo", "models", "node"]
