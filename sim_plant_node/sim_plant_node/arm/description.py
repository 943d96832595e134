"""The six-axis arm: published figures, modelling choices, and the URDF written from them.

The kinematics and link masses are those Universal Robots publishes for the UR5e ("DH
parameters for calculations of kinematics and dynamics", Universal Robots support article,
UR e-Series table): standard Denavit-Hartenberg parameters

    joint   d (m)    a (m)     alpha (rad)
    1       0.1625   0          pi/2
    2       0       -0.425      0
    3       0       -0.3922     0
    4       0.1333   0          pi/2
    5       0.0997   0         -pi/2
    6       0.0996   0          0

masses 3.761, 8.058, 2.846, 1.37, 1.3, 0.365 kg, centres of mass in the DH frame of each link
(table below, m), and joint torque limits 150, 150, 150, 28, 28, 28 N m.

What UR does not publish is chosen here and said so (docs/design/arm.md):

- Link inertia tensors: each link a uniform solid cylinder of its published mass, along x of
  its DH frame for the two long links (length |a|) and along z otherwise (length
  :data:`SHORT_LINK_LENGTH`), radii :data:`LINK_RADII` from the arm's tube and joint sizes.
- A payload at the flange (gripper and part), :data:`PAYLOAD_MASS` at
  :data:`PAYLOAD_OFFSET` along the flange's z, a cylinder of radius :data:`PAYLOAD_RADIUS`
  (:func:`payload_inertia`); the simulator changes it at run time
  (:meth:`~sim_plant_node.arm.dynamics.ArmModel.set_payload`).
- Joint elasticity (each joint a motor driving its link through a torsional spring and
  damper): stiffness :data:`JOINT_STIFFNESS` so that the lowest mode lies at 6 to 12 Hz over
  the workspace, as measured on arms of this size (Wu et al., "Experimental modal analysis of
  a collaborative robot", Intelligent Robotics 1(2), 2021: UR5 lowest modes 7.9 to 9.0 Hz
  empty and 6.0 to 6.5 Hz with a payload); damping proportional to stiffness,
  :data:`DAMPING_TIME` s, about 3 % of critical at the lowest mode.
- Motor side: reflected rotor inertia :data:`MOTOR_INERTIA` (rotor inertia times the square
  of a 101:1 harmonic drive), viscous friction :data:`MOTOR_FRICTION`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from xml.sax.saxutils import quoteattr

import numpy as np

#: joint names as the UR driver (ur_robot_driver) names them
JOINT_NAMES = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
               "wrist_3_joint")
#: UR5e standard DH parameters (Universal Robots, published)
DH_D = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
DH_A = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
#: link masses, kg (published)
LINK_MASSES = (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)
#: centres of mass in each link's DH frame, m (published)
LINK_COMS = ((0.0, -0.02561, 0.00193), (0.2125, 0.0, 0.11336), (0.15, 0.0, 0.0265), (0.0, -0.0018, 0.01634),
             (0.0, 0.0018, 0.01634), (0.0, 0.0, -0.001159))
#: joint torque limits, N m (published)
TORQUE_LIMITS = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)
#: chosen: cylinder radii of the links, m (the UR5e's tubes are about 0.09 m across, its joints 0.09 to 0.12 m)
LINK_RADII = (0.06, 0.054, 0.045, 0.0375, 0.0375, 0.0375)
#: chosen: length of the links without an ``a`` (the joint housings), m
SHORT_LINK_LENGTH = 0.12
#: chosen: the payload (gripper and part) at the flange, kg and m along the flange's z
PAYLOAD_MASS = 2.0
PAYLOAD_OFFSET = 0.08
#: chosen: the payload's radius, m (a uniform cylinder along the flange's z, from the flange to twice the offset)
PAYLOAD_RADIUS = 0.04
#: the largest payload the simulator takes, kg and m (UR5e: rated 5 kg; beyond, its model is not meant to hold)
MAX_PAYLOAD_MASS = 20.0
MAX_PAYLOAD_OFFSET = 0.5
#: chosen: torsional joint stiffness, N m/rad (see the module docstring)
JOINT_STIFFNESS = (1.0e4, 2.0e4, 1.2e4, 1.5e4, 1.5e4, 1.5e4)
#: chosen: joint damping = DAMPING_TIME x stiffness, s
DAMPING_TIME = 0.5e-3
#: chosen: reflected motor (rotor) inertia, kg m^2, and motor viscous friction, N m s/rad
MOTOR_INERTIA = (1.2, 1.2, 0.8, 0.15, 0.15, 0.15)
MOTOR_FRICTION = (2.0, 2.0, 1.5, 0.4, 0.4, 0.4)
#: the frame of the tool flange (and its IMU)
TOOL_FRAME = "tool0"


@dataclass(frozen=True)
class ArmSpec:
    """Everything that defines the simulated arm; the defaults are the module's figures."""

    d: tuple[float, ...] = DH_D
    a: tuple[float, ...] = DH_A
    alpha: tuple[float, ...] = DH_ALPHA
    masses: tuple[float, ...] = LINK_MASSES
    coms: tuple[tuple[float, float, float], ...] = LINK_COMS
    radii: tuple[float, ...] = LINK_RADII
    payload_mass: float = PAYLOAD_MASS
    payload_offset: float = PAYLOAD_OFFSET
    stiffness: tuple[float, ...] = JOINT_STIFFNESS
    damping_time: float = DAMPING_TIME
    motor_inertia: tuple[float, ...] = MOTOR_INERTIA
    motor_friction: tuple[float, ...] = MOTOR_FRICTION
    torque_limits: tuple[float, ...] = TORQUE_LIMITS
    joint_names: tuple[str, ...] = field(default=JOINT_NAMES)

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        for name in ("d", "a", "alpha", "masses", "coms", "radii", "stiffness", "motor_inertia", "motor_friction",
                     "torque_limits"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"ArmSpec.{name} needs {n} values, one per joint")
        for name in ("masses", "radii", "stiffness", "motor_inertia"):
            if not all(math.isfinite(v) and v > 0 for v in getattr(self, name)):
                raise ValueError(f"ArmSpec.{name} must be finite and > 0")
        if not (math.isfinite(self.damping_time) and self.damping_time >= 0):
            raise ValueError("ArmSpec.damping_time must be finite and >= 0")
        check_payload(self.payload_mass, self.payload_offset)

    @property
    def damping(self) -> np.ndarray:
        """Joint damping, N m s/rad."""
        return self.damping_time * np.asarray(self.stiffness)


def check_payload(mass: float, offset: float) -> None:
    """Refuse a payload the model cannot take: mass in [0, MAX_PAYLOAD_MASS] kg, offset in [0, MAX_PAYLOAD_OFFSET] m.

    Raises
    ------
    ValueError
        Naming the value and its range.
    """
    if not (isinstance(mass, (int, float)) and math.isfinite(mass) and 0.0 <= mass <= MAX_PAYLOAD_MASS):
        raise ValueError(f"payload mass must be finite and in [0, {MAX_PAYLOAD_MASS:g}] kg, got {mass!r}")
    if not (isinstance(offset, (int, float)) and math.isfinite(offset) and 0.0 <= offset <= MAX_PAYLOAD_OFFSET):
        raise ValueError(f"payload offset must be finite and in [0, {MAX_PAYLOAD_OFFSET:g}] m along the flange's z,"
                         f" got {offset!r}")


def payload_inertia(mass: float, offset: float) -> np.ndarray:
    """The payload's inertia tensor about its centre of mass, kg m^2 (a uniform solid cylinder of radius
    :data:`PAYLOAD_RADIUS` along the flange's z, from the flange to ``2 offset`` m; ``mass`` kg)."""
    return _cylinder(mass, PAYLOAD_RADIUS, 2 * offset, 2)


def _cylinder(mass: float, radius: float, length: float, axis: int) -> np.ndarray:
    """Inertia tensor of a uniform solid cylinder about its centre, kg m^2, its axis along ``axis``."""
    along = 0.5 * mass * radius**2
    across = mass * (3 * radius**2 + length**2) / 12.0
    diag = [across] * 3
    diag[axis] = along
    return np.diag(diag)


def _origin(xyz: tuple[float, float, float] | np.ndarray, rpy: tuple[float, float, float]) -> str:
    return (f'<origin xyz="{xyz[0]:.9g} {xyz[1]:.9g} {xyz[2]:.9g}" '
            f'rpy="{rpy[0]:.9g} {rpy[1]:.9g} {rpy[2]:.9g}"/>')


def _inertial(mass: float, com: np.ndarray, rpy: tuple[float, float, float], inertia: np.ndarray) -> str:
    i = inertia
    return (f"<inertial>{_origin(com, rpy)}<mass value=\"{mass:.9g}\"/>"
            f'<inertia ixx="{i[0, 0]:.9g}" ixy="{i[0, 1]:.9g}" ixz="{i[0, 2]:.9g}" iyy="{i[1, 1]:.9g}" '
            f'iyz="{i[1, 2]:.9g}" izz="{i[2, 2]:.9g}"/></inertial>')


def urdf(spec: ArmSpec | None = None, name: str = "ur5e_elastic") -> str:
    """The arm's URDF (rigid links; the joints' elasticity is the simulator's, not URDF's).

    Each link's frame is the DH frame of the previous link turned by the joint angle, so a joint's
    origin carries the previous link's constant DH transform ``Tz(d) Tx(a) Rx(alpha)`` and every
    joint turns about its z axis. The link's inertial block is in its own DH frame (published
    centre of mass), reached by the same transform. ``tool0`` is the flange (DH frame 6).
    """
    spec = spec or ArmSpec()
    n = len(spec.joint_names)
    parts = [f"<?xml version=\"1.0\"?><robot name={quoteattr(name)}>", '<link name="base_link"/>']
    parent = "base_link"
    for i in range(n):
        link = f"link_{i + 1}"
        prev = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) if i == 0 else \
            ((spec.a[i - 1], 0.0, spec.d[i - 1]), (spec.alpha[i - 1], 0.0, 0.0))
        limit = spec.torque_limits[i]
        parts.append(f'<joint name={quoteattr(spec.joint_names[i])} type="revolute">'
                     f'<parent link="{parent}"/><child link="{link}"/>{_origin(*prev)}<axis xyz="0 0 1"/>'
                     f'<limit lower="-6.283185307" upper="6.283185307" effort="{limit:g}" velocity="3.14159"/>'
                     "</joint>")
        long_link = abs(spec.a[i]) > 1e-9
        length = abs(spec.a[i]) if long_link else SHORT_LINK_LENGTH
        inertia = _cylinder(spec.masses[i], spec.radii[i], length, 0 if long_link else 2)
        # the centre of mass is given in DH frame i = this link's frame moved by Tz(d) Tx(a) Rx(alpha)
        c = np.asarray(spec.coms[i], dtype=float)
        ca, sa = math.cos(spec.alpha[i]), math.sin(spec.alpha[i])
        com = np.array([spec.a[i] + c[0], ca * c[1] - sa * c[2], spec.d[i] + sa * c[1] + ca * c[2]])
        parts.append(f'<link name="{link}">{_inertial(spec.masses[i], com, (spec.alpha[i], 0.0, 0.0), inertia)}</link>')
        parent = link
    parts.append(f'<joint name="flange" type="fixed"><parent link="{parent}"/><child link="{TOOL_FRAME}"/>'
                 f'{_origin((spec.a[-1], 0.0, spec.d[-1]), (spec.alpha[-1], 0.0, 0.0))}</joint>')
    if spec.payload_mass > 0:
        payload = _inertial(spec.payload_mass, np.array([0.0, 0.0, spec.payload_offset]), (0.0, 0.0, 0.0),
                            payload_inertia(spec.payload_mass, spec.payload_offset))
        parts.append(f'<link name="{TOOL_FRAME}">{payload}</link>')
    else:
        parts.append(f'<link name="{TOOL_FRAME}"/>')
    parts.append("</robot>")
    return "\n".join(parts)
