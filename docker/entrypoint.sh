#!/bin/bash
# Entrypoint of the shaper image: source the ROS 2 Jazzy underlay and the suite's overlay,
# then run the command (by default `ros2 run shaper_nodes shaper_node ...`, see Dockerfile).
# tini runs this script as its child, so `exec` keeps the command in tini's process group
# and `docker stop` (SIGINT) reaches it and the node that `ros2 run` starts.
set -e

# The setup files read unset variables, so they are sourced without `set -u`; the `--`
# keeps them from seeing this script's arguments (the command) as their own, as in the
# official ros_entrypoint.sh.
# shellcheck disable=SC1091
source /opt/ros/jazzy/setup.bash --
# shellcheck disable=SC1091
source /ws/install/setup.bash --

if [ "$#" -eq 0 ]; then
  set -- bash
fi
exec "$@"
