#!/usr/bin/env bash
# Create (or refresh) the project venv with what a plain machine needs to run the package:
# numpy, scipy, numba, ..., the ROS 2 PyPI wheels of $ROS_DISTRO (kilted, the default, into
# .venv; jazzy into .venv-jazzy; rclpy + messages + Fast DDS) and this package in editable
# mode.  No test or lint tool: `--dev` adds requirements/dev.txt on top (pytest, ruff, mypy,
# hypothesis, colcon, the docs tools; scripts/run_tests.sh does it).
#   scripts/setup_env.sh           # run-time (scripts/run_demo.sh, run_pass.sh call this)
#   scripts/setup_env.sh --dev     # run-time + developer's tools
# Idempotent: re-installs only when a requirements file, setup.py or package.xml changed since
# the last successful run.  VENV overrides the venv path, PYTHON the interpreter (3.11+).
set -euo pipefail
cd "$(dirname "$0")/.."
DEV=0
case "${1:-}" in
    --dev) DEV=1 ;;
    "") ;;
    *) echo "setup_env.sh: unknown option '$1' (only --dev)" >&2; exit 2 ;;
esac
# shellcheck source=scripts/ros_distro.sh
. scripts/ros_distro.sh
PY=${PYTHON:-python3}
if [ ! -x "$VENV/bin/python" ]; then
    echo "[setup] creating $VENV ($ROS_DISTRO) with $($PY --version)"
    "$PY" -m venv "$VENV"
fi
# pip, its warnings about an index or a find-links folder in the machine's pip configuration
# that does not exist left out (one line per package for such a machine, not this project's);
# every other line, and pip's exit status, kept.
pip_install() {
    "$VENV/bin/python" -m pip install --quiet "$@" 2>&1 \
        | { grep -v -F 'is ignored: it is neither a file nor a directory' || true; }
}
stamp="$VENV/.worm_gear_sim_installed"
if [ ! -f "$stamp" ] || [ requirements.txt -nt "$stamp" ] || [ "$ROS_REQUIREMENTS" -nt "$stamp" ] \
        || [ setup.py -nt "$stamp" ] || [ package.xml -nt "$stamp" ]; then
    echo "[setup] installing requirements into $VENV (PyPI: numpy, scipy, numba, ROS 2" \
         "$ROS_DISTRO wheels; first run: about two minutes)"
    pip_install --upgrade pip 'setuptools>=61,<80' wheel
    pip_install -r requirements.txt -r "$ROS_REQUIREMENTS"
    # Editable install: no data_files; the package finds config/ in the source tree.  (Python's
    # warnings off for it: setuptools warns, in a 12-line banner, that a folder named like the
    # package in the working directory may shadow it; here that folder is the package.)
    PYTHONWARNINGS=ignore pip_install --no-deps --no-build-isolation -e .
    touch "$stamp"
fi
dev_stamp="$VENV/.worm_gear_sim_dev_installed"
if [ "$DEV" = 1 ] && { [ ! -f "$dev_stamp" ] || [ requirements/dev.txt -nt "$dev_stamp" ] \
        || [ "$stamp" -nt "$dev_stamp" ]; }; then
    echo "[setup] installing the developer's tools into $VENV (requirements/dev.txt)"
    pip_install -r requirements/dev.txt
    touch "$dev_stamp"
fi
# The PyPI ROS wheels re-exec Python once to set LD_LIBRARY_PATH; check that rclpy works.
if ! "$VENV/bin/python" -c "import rclpy, std_msgs.msg, std_srvs.srv, sensor_msgs.msg, diagnostic_msgs.msg, trajectory_msgs.msg" \
        >/dev/null 2>&1; then
    echo "[setup] ERROR: rclpy or the ROS message packages do not import in $VENV" >&2
    "$VENV/bin/python" -c "import rclpy" >&2 || true
    exit 1
fi
# numba's on-disk cache (cache=True) is checked against the file of each compiled function
# only: a kernel whose callee changed in another module would load stale machine code.  Any
# change to the package's sources clears the package's numba cache (the package does the same
# when it is first imported: worm_gear_sim/_support/kernel_cache.py).
"$VENV/bin/python" -c "from worm_gear_sim._support.kernel_cache import ensure_fresh_cache as f; f()"
