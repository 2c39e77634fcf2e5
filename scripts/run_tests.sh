#!/usr/bin/env bash
# The whole test suite: set-up (idempotent), lint, then every test. Extra arguments go to
# pytest (e.g. scripts/run_tests.sh -k radau). DDS traffic stays on this machine.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup_env.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-42}
export MPLBACKEND=Agg
echo "[tests] ruff check ."
.venv/bin/ruff check .
echo "[tests] pytest"
exec .venv/bin/python -m pytest "$@"
