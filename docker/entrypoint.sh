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

# SROS2 (docs/guide/security.md): with ROS_SECURITY_ENABLE=true, check before starting that the keystore
# is mounted and that the enclave named by --enclave (or ROS_SECURITY_ENCLAVE_OVERRIDE) has its
# files, and say which is missing; DDS would otherwise fail later with a less direct message.
if [ "${ROS_SECURITY_ENABLE:-}" = "true" ]; then
  keystore="${ROS_SECURITY_KEYSTORE:-}"
  if [ -z "${keystore}" ] || [ ! -d "${keystore}/enclaves" ]; then
    echo "shaper-entrypoint: ROS_SECURITY_ENABLE=true but ROS_SECURITY_KEYSTORE (${keystore:-unset}) has no" \
         "enclaves/ folder: mount the keystore (docs/guide/security.md)" >&2
    exit 1
  fi
  enclave="${ROS_SECURITY_ENCLAVE_OVERRIDE:-}"
  previous=""
  for arg in "$@"; do
    if [ "${previous}" = "--enclave" ] || [ "${previous}" = "-e" ]; then
      enclave="${ROS_SECURITY_ENCLAVE_OVERRIDE:-${arg}}"
    fi
    previous="${arg}"
  done
  if [ -n "${enclave}" ]; then
    for file in cert.pem key.pem identity_ca.cert.pem permissions_ca.cert.pem governance.p7s permissions.p7s; do
      if [ ! -r "${keystore}/enclaves${enclave}/${file}" ]; then
        echo "shaper-entrypoint: enclave ${enclave}: ${keystore}/enclaves${enclave}/${file} is missing or" \
             "unreadable by UID $(id -u) (mount that enclave's folder; its key must be readable by this user)" >&2
        exit 1
      fi
    done
  fi
fi
exec "$@"
