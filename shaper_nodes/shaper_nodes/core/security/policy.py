"""The suite's access policy table (:func:`suite_policy`): which enclave publishes and subscribes which topic,
serves and calls which service and action, from the suite's names (:data:`DEFAULT_NAMES`); extra grants."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import replace

from .names import Access, Verb, node_fqn, resolve

__all__ = ["DEFAULT_NAMES", "names_with", "suite_policy", "with_grants"]


#: The suite's node names, topics and services that the table refers to, with their defaults (the
#: nodes' own parameter defaults: ``topics.*`` of nodes/shaper.py, ``action.*``, ``shaper``,
#: ``mrilc.*`` ...). ``node.*`` are node names (in ``namespace``); the other values are ROS names,
#: ``~/x`` being relative to the node that owns them.
DEFAULT_NAMES: dict[str, str] = {
    "namespace": "/",
    "node.shaper": "shaper",
    "node.learner": "learner",
    "node.scheduler": "scheduler",
    "node.identifier": "identifier",
    "node.calibrate": "calibrate",
    "node.recorder": "recorder",
    "node.motion_source": "motion_source",
    # the controller side (ros2_control): the controller manager and its controllers are nodes
    "node.controller": "controller_manager,joint_trajectory_controller,forward_position_controller,"
                       "joint_state_broadcaster,imu_sensor_broadcaster",
    # the shaper node's topics.* (nodes/shaper.py TOPICS)
    "topics.array_in": "~/commands",
    "topics.array_out": "/forward_position_controller/commands",
    "topics.stream_in": "~/joint_trajectory_stream",
    "topics.stream_out": "/joint_trajectory_controller/joint_trajectory",
    "topics.trajectory_in": "~/joint_trajectory",
    "topics.trajectory_out": "/joint_trajectory_controller/joint_trajectory",
    # the shaper node's action.*: its FollowJointTrajectory server and the controller's
    "action.server_name": "~/follow_joint_trajectory",
    "action.controller": "/joint_trajectory_controller/follow_joint_trajectory",
    # what the learners, the identifier, the scheduler and calibrate read (their topics.* defaults)
    "topics.joint_states": "/joint_states",
    "topics.imu": "/tip_imu",
    "topics.cycle_events": "/cycle_events",
    "topics.reference": "/sim_plant/reference",
    "topics.diagnostics": "/diagnostics",
    # MRILC's injection point: the node that serves ~/set_feedforward (controller side)
    "mrilc.injection_target": "/sim_plant",
}


def names_with(overrides: Mapping[str, str] | None = None) -> dict[str, str]:
    """:data:`DEFAULT_NAMES` with ``overrides``; an unknown key is an error naming the known ones."""
    names = dict(DEFAULT_NAMES)
    for key, value in (overrides or {}).items():
        if key not in names:
            raise ValueError(f"unknown name {key!r}; known: {', '.join(sorted(names))}")
        names[key] = value
    return names


def suite_policy(overrides: Mapping[str, str] | None = None) -> dict[str, Access]:
    """The suite's access policy: enclave role -> :class:`Access` (the table of docs/guide/security.md).

    - ``shaper``: serves ``~/set_shaper``, ``~/get_shaper``, ``~/shape_trajectory`` and its
      FollowJointTrajectory action, reads the command inputs, publishes the shaped commands,
      ``~/active_shaper`` and diagnostics, calls the controller's action and (``action.scheduler``)
      the scheduler's ``~/shaper_at``.
    - ``learner``, ``scheduler``, ``identifier``, ``calibrate``: the only callers of the shaper's
      ``~/set_shaper`` (the learner also of the scheduler's, when it is pointed at it, and, learning per
      move, of its ``~/set_move_shaper`` and ``~/shaper_at``).
    - ``motion_source``: the only publisher of the shaper's command inputs, the only client of its
      action and ``~/shape_trajectory``; it marks the cycles (``/cycle_events``).
    - ``recorder``: reads every topic of the table, publishes none of them.
    - ``controller``: ros2_control: reads the shaped commands, serves the controller's action,
      publishes joint states and the accelerometer, serves MRILC's ``~/set_feedforward`` and
      publishes the applied reference; its controller manager's services (and the spawner's
      calls to them) as patterns.

    Parameters
    ----------
    overrides : mapping of str to str, optional
        Keys of :data:`DEFAULT_NAMES` (node names, namespace, topics) to change.
    """
    n = names_with(overrides)
    ns = n["namespace"]

    def fqn(role: str) -> str:
        return node_fqn(ns, n[f"node.{role}"])

    shaper = fqn("shaper")
    scheduler = fqn("scheduler")

    def of_shaper(key: str) -> str:
        return resolve(n[key], ns, n["node.shaper"])

    commands_in = frozenset(of_shaper(f"topics.{k}") for k in ("array_in", "stream_in", "trajectory_in"))
    commands_out = frozenset(of_shaper(f"topics.{k}") for k in ("array_out", "stream_out", "trajectory_out"))
    shaper_action = of_shaper("action.server_name")
    controller_action = resolve(n["action.controller"], ns, "")
    joint_states, imu, events, reference, diagnostics = (
        resolve(n[f"topics.{k}"], ns, "") for k in ("joint_states", "imu", "cycle_events", "reference", "diagnostics"))
    set_get = frozenset({f"{shaper}/set_shaper", f"{shaper}/get_shaper"})
    feedforward = f"{resolve(n['mrilc.injection_target'], ns, '')}/set_feedforward"
    controller_nodes = tuple(node_fqn(ns, x) for x in n["node.controller"].split(",") if x.strip())
    if not controller_nodes:
        raise ValueError("node.controller must name at least one node")
    manager = controller_nodes[0]

    policy = {
        "shaper": Access(
            nodes=(shaper, f"{shaper}_trajectories"),
            publish=commands_out | {f"{shaper}/active_shaper", diagnostics},
            subscribe=commands_in,
            serve=set_get | {f"{shaper}/shape_trajectory"},
            call=frozenset({f"{scheduler}/shaper_at"}),
            serve_actions=frozenset({shaper_action}),
            call_actions=frozenset({controller_action})),
        "learner": Access(
            nodes=(fqn("learner"),),
            publish=frozenset({f"{fqn('learner')}/reports", diagnostics}),
            subscribe=frozenset({imu, events, joint_states, reference, f"{shaper}/active_shaper",
                                 f"{scheduler}/active_shaper"}),
            serve=frozenset({f"{fqn('learner')}/hold"}),
            call=set_get | {f"{scheduler}/set_shaper", f"{scheduler}/get_shaper", feedforward,
                            f"{scheduler}/set_move_shaper", f"{scheduler}/shaper_at"}),  # (list.per_move)
        "scheduler": Access(
            nodes=(scheduler,),
            publish=frozenset({f"{scheduler}/active_shaper", f"{scheduler}/mode_estimate", diagnostics}),
            subscribe=frozenset({joint_states, f"{shaper}/active_shaper"}),
            serve=frozenset({f"{scheduler}/set_shaper", f"{scheduler}/get_shaper", f"{scheduler}/shaper_at",
                             f"{scheduler}/set_move_shaper"}),
            call=set_get),
        "identifier": Access(
            nodes=(fqn("identifier"),),
            publish=frozenset({f"{fqn('identifier')}/mode_estimate", diagnostics}),
            subscribe=frozenset({imu, joint_states, events}),
            serve=frozenset({f"{fqn('identifier')}/identify"}),
            call=set_get),
        "calibrate": Access(
            nodes=(fqn("calibrate"),),
            subscribe=frozenset({imu, joint_states}),
            call=set_get,
            call_actions=frozenset({controller_action})),
        "motion_source": Access(
            nodes=(fqn("motion_source"),),
            publish=commands_in | {events},
            subscribe=frozenset({f"{shaper}/active_shaper"}),
            call=frozenset({f"{shaper}/shape_trajectory"}),
            call_actions=frozenset({shaper_action})),
        "controller": Access(
            nodes=controller_nodes,
            publish=frozenset({joint_states, imu, reference}),
            subscribe=commands_out,
            serve=frozenset({feedforward}),
            serve_actions=frozenset({controller_action}),
            # the controller manager's own services, served and called (by the spawner) in this enclave
            dds_publish=frozenset({f"rr{manager}/*", f"rq{manager}/*"}),
            dds_subscribe=frozenset({f"rq{manager}/*", f"rr{manager}/*"})),
    }
    every_topic: set[str] = set()
    for access in policy.values():
        every_topic |= access.publish | access.subscribe
    policy["recorder"] = Access(nodes=(fqn("recorder"),), subscribe=frozenset(every_topic),
                                serve=frozenset({f"{fqn('recorder')}/stop"}))
    return policy


def with_grants(policy: Mapping[str, Access], grants: Iterable[tuple[str, Verb, str]]) -> dict[str, Access]:
    """``policy`` with extra DDS topics or patterns granted: ``(role, verb, dds_topic)`` each, for
    interfaces outside the suite (MoveIt's, a driver's). A pattern (``rt/move_group/*``) also
    lifts the role's explicit denials that it matches."""
    out = dict(policy)
    for role, verb, topic in grants:
        if role not in out:
            raise ValueError(f"unknown role {role!r}; roles: {', '.join(out)}")
        if verb not in ("publish", "subscribe"):
            raise ValueError(f"verb must be publish or subscribe, got {verb!r}")
        topic = topic.strip()
        if not topic or any(c.isspace() or c in "<>&" for c in topic):
            raise ValueError(f"{topic!r} is not a DDS topic name or pattern")
        a = out[role]
        if verb == "publish":
            out[role] = replace(a, dds_publish=a.dds_publish | {topic})
        else:
            out[role] = replace(a, dds_subscribe=a.dds_subscribe | {topic})
    return out
