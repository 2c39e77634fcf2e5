#!/usr/bin/env bash
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
#
# Set up (first run) and run the worm_gear_sim ROS 2 node twice on one stream, with and
# without the feed-forward, beside the demo servo (worm_gear_sim.ros.demo_commander), which
# waits until both are ready, streams the reference and shows the antenna error each one
# predicts side by side (one line on a terminal, a table of one row per move otherwise) and
# a summary.  It stops the nodes before its stream: Ctrl-C or the end are quiet, exit 0.
#
#   scripts/run_demo.sh [DURATION_S] [paper|slew]
#
# Environment:
#   DEMO_DURATION     seconds of streaming (default 20)
#   DEMO_PATTERN      paper | slew (default paper)
#   DEMO_NODES        both (default) | compensated | uncompensated: /worm_gear_sim with the
#                     feed-forward applied (node.compensation_applied), /uncompensated/
#                     worm_gear_sim without; one of them alone on a slower machine
#   DEMO_INTERFACE    stamped | float64 (default: the demo's, see --interface)
#   DEMO_PREVIEW      seconds the servo streams ahead (compensation.preview_time), e.g. 0.002
#   ROS_DISTRO        kilted (default, .venv) | jazzy (.venv-jazzy); VENV overrides the venv
#   ROS_DOMAIN_ID     default: yours, or 0; ROS_AUTOMATIC_DISCOVERY_RANGE default LOCALHOST
# Needs python3 (3.11 or newer with venv); the ROS 2 PyPI wheels come from requirements/.
set -euo pipefail

cd "$(dirname "$0")/.."
case "${1:-}" in
    -h|--help) sed -n '5,23p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
esac
DURATION="${1:-${DEMO_DURATION:-20}}"
PATTERN="${2:-${DEMO_PATTERN:-paper}}"
NODES="${DEMO_NODES:-both}"
if ! [[ "$DURATION" =~ ^[0-9]+([.][0-9]+)?$ ]]; then
    echo "run_demo.sh: DURATION_S must be a number of seconds, got '$DURATION' (see --help)" >&2
    exit 2
fi
if [ "$PATTERN" != paper ] && [ "$PATTERN" != slew ]; then
    echo "run_demo.sh: pattern must be paper or slew, got '$PATTERN' (see --help)" >&2
    exit 2
fi
case "$NODES" in
    both|compensated|uncompensated) ;;
    *) echo "run_demo.sh: DEMO_NODES must be both, compensated or uncompensated, got" \
            "'$NODES' (see --help)" >&2
       exit 2 ;;
esac
# shellcheck source=scripts/ros_distro.sh
. scripts/ros_distro.sh                # ROS_DISTRO=kilted (.venv, default) | jazzy (.venv-jazzy)
scripts/setup_env.sh                   # creates the venv and installs everything (first run)
PY="$VENV/bin/python"

export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
CONFIG="$("$PY" -c 'from worm_gear_sim.config.files import default_config_path; print(default_config_path())')"

COMMON=(--ros-args --params-file "$CONFIG" --log-level warn)
if [ -n "${DEMO_PREVIEW:-}" ]; then
    COMMON+=(-p "compensation.preview_time:=$DEMO_PREVIEW")
fi
DEMO_ARGS=(--duration "$DURATION" --pattern "$PATTERN" --config "$CONFIG")
if [ -n "${DEMO_INTERFACE:-}" ]; then
    DEMO_ARGS+=(--interface "$DEMO_INTERFACE")
fi
PIDS=()
start_node() {    # NAME ARGS...: a node in the background, its pid for the demo to stop
    local name="$1"
    shift
    "$PY" -m worm_gear_sim.ros "${COMMON[@]}" "$@" &
    PIDS+=($!)
    DEMO_ARGS+=(--node "$name" --node-pid "$!")
    echo "[demo] ROS 2 $ROS_DISTRO: node $name pid $!"
}
if [ "$NODES" != uncompensated ]; then
    start_node /worm_gear_sim -p node.compensation_applied:=true
else
    start_node /worm_gear_sim
fi
if [ "$NODES" = both ]; then
    # the same stream: the reference topics remapped out of its namespace
    start_node /uncompensated/worm_gear_sim -r __ns:=/uncompensated \
        -r worm_angle_reference:=/worm_angle_reference \
        -r worm_angle_command:=/worm_angle_command
fi
stop_nodes() {    # the nodes the demo has not stopped (an error exit, a hang-up): SIGTERM
    local rc=0 pid
    for pid in "${PIDS[@]}"; do
        kill -TERM "$pid" 2>/dev/null || true   # background jobs of a script ignore SIGINT
    done
    for pid in "${PIDS[@]}"; do
        wait "$pid" 2>/dev/null || rc=$?
    done
    return $rc
}
# the nodes never outlive the script: also on its own error exit, a hang-up or a broken pipe
trap 'stop_nodes || true' EXIT
trap 'exit 143' TERM
trap 'exit 129' HUP
trap 'exit 141' PIPE
# Ctrl-C reaches the demo (the foreground job), which stops the nodes and ends with 0: the
# script then goes on as after a normal end (the trap only keeps bash from exiting at once)
trap ':' INT

set +e
"$PY" -m worm_gear_sim.ros.demo_commander "${DEMO_ARGS[@]}"
DEMO_RC=$?
stop_nodes
NODE_RC=$?
set -e
trap - EXIT
echo "[demo] demo exit code $DEMO_RC, node exit code $NODE_RC"
if [ "$DEMO_RC" -ne 0 ]; then exit "$DEMO_RC"; fi
exit "$NODE_RC"
