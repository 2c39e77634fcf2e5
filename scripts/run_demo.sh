#!/usr/bin/env bash
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
#
# Set up (first run) and run the worm_gear_sim ROS 2 node with the demo servo
# (worm_gear_sim.ros.demo_commander) streaming a reference to it; shows the predicted antenna
# error live (one line on a terminal, one line per move otherwise) and a summary.
#
#   scripts/run_demo.sh [DURATION_S] [paper|slew]
#
# Environment:
#   DEMO_DURATION     seconds of streaming (default 20)
#   DEMO_PATTERN      paper | slew (default paper)
#   DEMO_INTERFACE    stamped | float64 (default: the demo's, see --interface)
#   DEMO_COMPENSATED  1: the node predicts with its feed-forward applied
#                     (node.compensation_applied), the demo reports the benefit in numbers
#   DEMO_PREVIEW      seconds the servo streams ahead (compensation.preview_time), e.g. 0.002
#   ROS_DISTRO        kilted (default, .venv) | jazzy (.venv-jazzy); VENV overrides the venv
#   ROS_DOMAIN_ID     default: yours, or 0; ROS_AUTOMATIC_DISCOVERY_RANGE default LOCALHOST
# Needs python3 (3.11 or newer with venv); the ROS 2 PyPI wheels come from requirements/.
set -euo pipefail

cd "$(dirname "$0")/.."
case "${1:-}" in
    -h|--help) sed -n '5,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
esac
DURATION="${1:-${DEMO_DURATION:-20}}"
PATTERN="${2:-${DEMO_PATTERN:-paper}}"
if ! [[ "$DURATION" =~ ^[0-9]+([.][0-9]+)?$ ]]; then
    echo "run_demo.sh: DURATION_S must be a number of seconds, got '$DURATION' (see --help)" >&2
    exit 2
fi
if [ "$PATTERN" != paper ] && [ "$PATTERN" != slew ]; then
    echo "run_demo.sh: pattern must be paper or slew, got '$PATTERN' (see --help)" >&2
    exit 2
fi
# shellcheck source=scripts/ros_distro.sh
. scripts/ros_distro.sh                # ROS_DISTRO=kilted (.venv, default) | jazzy (.venv-jazzy)
scripts/setup_env.sh                   # creates the venv and installs everything (first run)
PY="$VENV/bin/python"

export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
CONFIG="$("$PY" -c 'from worm_gear_sim.config_io import default_config_path; print(default_config_path())')"

NODE_ARGS=(--ros-args --params-file "$CONFIG" --log-level warn)
DEMO_ARGS=(--duration "$DURATION" --pattern "$PATTERN" --config "$CONFIG")
if [ "${DEMO_COMPENSATED:-0}" = "1" ]; then
    NODE_ARGS+=(-p node.compensation_applied:=true)
fi
if [ -n "${DEMO_PREVIEW:-}" ]; then
    NODE_ARGS+=(-p "compensation.preview_time:=$DEMO_PREVIEW")
fi
if [ -n "${DEMO_INTERFACE:-}" ]; then
    DEMO_ARGS+=(--interface "$DEMO_INTERFACE")
fi
"$PY" -m worm_gear_sim.ros "${NODE_ARGS[@]}" &
NODE_PID=$!
echo "[demo] ROS 2 $ROS_DISTRO: node pid $NODE_PID ${NODE_ARGS[*]:5}"
stop_node() {
    if kill -0 "$NODE_PID" 2>/dev/null; then
        kill -TERM "$NODE_PID" 2>/dev/null || true   # background jobs of a script ignore SIGINT
        wait "$NODE_PID" 2>/dev/null
        return $?
    fi
    wait "$NODE_PID" 2>/dev/null
}
# the node never outlives the script: also on its own error exit, a hang-up or a broken pipe
trap 'stop_node || true' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
trap 'exit 129' HUP
trap 'exit 141' PIPE

set +e
"$PY" -m worm_gear_sim.ros.demo_commander "${DEMO_ARGS[@]}"
DEMO_RC=$?
stop_node
NODE_RC=$?
set -e
trap - EXIT
echo "[demo] demo exit code $DEMO_RC, node exit code $NODE_RC"
if [ "$DEMO_RC" -ne 0 ]; then exit "$DEMO_RC"; fi
exit "$NODE_RC"
