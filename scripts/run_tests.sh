#!/usr/bin/env bash
# The whole test suite: set-up with the developer's tools (idempotent), lint, types, then every
# test (the docs site and every documented command included), on the PyPI wheels of
# ROS_DISTRO (kilted, the default, in .venv; or jazzy, in .venv-jazzy):
#   scripts/run_tests.sh                      # Kilted
#   ROS_DISTRO=jazzy scripts/run_tests.sh     # Jazzy (LTS)
# Extra arguments go to pytest (e.g. scripts/run_tests.sh -k radau). The tests run on every core
# (pytest-xdist; PYTEST_WORKERS=1 runs them in one process). DDS traffic stays on this machine;
# pytest worker N uses ROS_DOMAIN_ID (default 42) + 2N in-process and + 2N + 1 for child processes.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=scripts/ros_distro.sh
. scripts/ros_distro.sh
scripts/setup_env.sh --dev
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-42}
export MPLBACKEND=Agg
echo "[tests] ROS 2 $ROS_DISTRO ($RCLPY_DIST $("$VENV/bin/python" -c \
    "from importlib.metadata import version; print(version('$RCLPY_DIST'))"), $VENV)"
echo "[tests] numba kernels into the cache (scripts/warm_kernels.py: compiled once, not per worker)"
"$VENV/bin/python" scripts/warm_kernels.py
echo "[tests] ruff check ."
"$VENV/bin/ruff" check .
echo "[tests] mypy (the core; configured in pyproject.toml)"
"$VENV/bin/python" -m mypy
echo "[tests] pytest"
workers=${PYTEST_WORKERS:-auto}
if [ "$workers" = 1 ]; then
    exec "$VENV/bin/python" -m pytest "$@"
fi
# One BLAS thread per worker: N workers on N cores each with N BLAS threads oversubscribe the
# cores (the fits' linear algebra).  Measured 2026-11-28 on 2 cores, nothing else running:
#   pytest -n 2 --dist loadfile test/identification/test_fit.py test/cli/test_calibrate_cli.py \
#          test/dynamics/test_backlash.py test/identification/test_direct.py
# 63.0 and 65.3 s with OPENBLAS_NUM_THREADS=1, 67.1 and 73.3 s without (alternating order).
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
# --dist loadfile: a module's tests stay on one worker, so module-scoped fixtures run once.
exec "$VENV/bin/python" -m pytest -n "$workers" --dist loadfile "$@"
