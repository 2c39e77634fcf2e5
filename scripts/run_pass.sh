#!/usr/bin/env bash
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
#
# Set up (first run) and run a satellite tracking pass through the two-axis pedestal:
# worm_gear_sim_pedestal (azimuth + elevation drives of config/pedestal.yaml) and a planner
# stand-in (worm_gear_sim.ros.pass_demo) that streams the pass as two-joint trajectories,
# checks each compensated trajectory against the offline twin and prints the per-axis
# pointing error with and without compensation (CSV + PNG in pass/).
#
#   scripts/run_pass.sh [DURATION_S] [MAX_ELEVATION_DEG]
#   scripts/run_pass.sh --adapt [DURATION_S] [MAX_ELEVATION_DEG]
#
# --adapt: the pass with live adaptation on both drives against a drive with play and load
# (config/pedestal_plant.yaml): the pedestal, a plant node per drive and the commander
# (worm_gear_sim.ros.live_pedestal) stream the pass as stamped samples on a simulated
# clock and print the pointing error over the last 10 s, uncompensated and adapting, and
# the twin's with the nominal feed-forward beside (PASS_TWIN=0: no twin).
#
# Environment: ROS_DISTRO kilted (default) | jazzy; ROS_DOMAIN_ID (default: yours, or 0);
# ROS_AUTOMATIC_DISCOVERY_RANGE (default LOCALHOST); PASS_OUTPUT (default pass); PASS_DURATION.
set -euo pipefail

cd "$(dirname "$0")/.."
ADAPT=0
case "${1:-}" in
    -h|--help) sed -n '5,21p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --adapt) ADAPT=1; shift ;;
esac
DURATION="${1:-${PASS_DURATION:-60}}"
ELEVATION="${2:-85}"
for v in "$DURATION" "$ELEVATION"; do
    if ! [[ "$v" =~ ^[0-9]+([.][0-9]+)?$ ]]; then
        echo "run_pass.sh: arguments must be numbers, got '$v' (see --help)" >&2
        exit 2
    fi
done
# shellcheck source=scripts/ros_distro.sh
. scripts/ros_distro.sh
scripts/setup_env.sh
PY="$VENV/bin/python"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"

if [ "$ADAPT" -eq 1 ]; then
    TWIN=(--twin)
    [ "${PASS_TWIN:-1}" = 0 ] && TWIN=()
    echo "[pass] ROS 2 $ROS_DISTRO: the pass with live adaptation (pedestal, two plants)"
    exec "$PY" -m worm_gear_sim.ros.live_pedestal --plant config/pedestal_plant.yaml \
        --duration "$DURATION" --max-elevation "$ELEVATION" -o "${PASS_OUTPUT:-pass}" \
        "${TWIN[@]}"
fi

"$PY" -c 'import sys; from worm_gear_sim.ros.startup import pedestal_main; sys.exit(pedestal_main())' \
    --ros-args --log-level warn &
PEDESTAL_PID=$!
echo "[pass] ROS 2 $ROS_DISTRO: pedestal pid $PEDESTAL_PID"
stop_pedestal() {
    if kill -0 "$PEDESTAL_PID" 2>/dev/null; then
        kill -TERM "$PEDESTAL_PID" 2>/dev/null || true
    fi
    wait "$PEDESTAL_PID" 2>/dev/null
}
trap 'stop_pedestal || true' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

set +e
"$PY" -m worm_gear_sim.ros.pass_demo --duration "$DURATION" --max-elevation "$ELEVATION" \
    -o "${PASS_OUTPUT:-pass}"
RC=$?
stop_pedestal
PED_RC=$?
set -e
trap - EXIT
if [ "$PED_RC" -ne 0 ]; then
    echo "[pass] the pedestal exited with $PED_RC" >&2
    [ "$RC" -eq 0 ] && RC=1
fi
exit "$RC"
