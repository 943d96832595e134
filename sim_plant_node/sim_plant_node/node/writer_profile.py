"""The Fast DDS times of the sim plant's writers: a profiles file the ``sim_plant`` executable names before it starts.

In lockstep with readers the plant writes six reliable samples a period (the reference, two IMU samples, the joint
state, the tip state, /clock) to each reader. With Fast DDS's default writer times every write to a reliable reader
fires that reader proxy's NACK-suppression event at once (``nackSupressionDuration`` 0): the middleware's event
thread woke for nearly every write (up to 6700 times per simulated s) beside the writing thread, and the plant's
process spent 0.073-0.100 CPU s per simulated s with one reader against 0.038-0.050 with none; with the profile
0.053-0.061 (docs/results/benchmarks.md, issue 34, session 10). The profile (``config/fastdds_writers.xml`` in the
package's share) sets the suppression to 10 ms and the periodic heartbeat to 100 ms; the QoS (reliability, history,
depth, durability) stays the node's, which rmw_fastrtps applies over a default profile. Nothing on the wire changes
but when heartbeats go and when a NACK is answered; reliability and the lockstep contract are untouched.

:func:`use_writer_profile` names the file in ``FASTRTPS_DEFAULT_PROFILES_FILE`` before ``rclpy.init`` unless the
environment already names one (a deployment's own profile wins) or asks rmw_fastrtps to take the QoS from XML
(then a default profile without QoS would replace the node's). Other RMW implementations ignore the variable.
"""

from __future__ import annotations

import os
import pathlib
from collections.abc import MutableMapping

__all__ = ["PROFILES_ENV", "PROFILE_FILE", "QOS_FROM_XML_ENV", "profile_path", "use_writer_profile"]

#: Fast DDS 2.x reads its XML profiles from the file this variable names, at its first participant
PROFILES_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
#: rmw_fastrtps takes the QoS from the XML profiles instead of the node's when this is true
QOS_FROM_XML_ENV = "RMW_FASTRTPS_USE_QOS_FROM_XML"
#: the profiles file, in the package's share/config
PROFILE_FILE = "fastdds_writers.xml"


def profile_path() -> pathlib.Path:
    """The installed profiles file (``share/sim_plant_node/config``)."""
    from ament_index_python.packages import get_package_share_directory

    return pathlib.Path(get_package_share_directory("sim_plant_node")) / "config" / PROFILE_FILE


def use_writer_profile(environ: MutableMapping[str, str] | None = None,
                       path: pathlib.Path | None = None) -> pathlib.Path | None:
    """Name the writers' profiles file in ``environ`` (``os.environ``: the process's own, read by Fast DDS at
    ``rclpy.init``) unless it names a profiles file already or ``RMW_FASTRTPS_USE_QOS_FROM_XML`` is set; the
    file named, or None when the environment was left as it was (also when the file is missing)."""
    env = os.environ if environ is None else environ
    if env.get(PROFILES_ENV) or env.get(QOS_FROM_XML_ENV, "").strip() not in ("", "0"):
        return None
    try:
        path = profile_path() if path is None else path
    except LookupError:  # (ament_index: the package is not installed in this environment)
        return None
    if not path.is_file():
        return None
    env[PROFILES_ENV] = str(path)
    return path
