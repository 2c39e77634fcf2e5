# Sourced by the scripts: which ROS 2 distro's PyPI wheels to use, and the venv that holds them.
#   ROS_DISTRO=kilted (default) -> .venv        requirements.txt + requirements/ros-kilted.txt
#   ROS_DISTRO=jazzy            -> .venv-jazzy  requirements.txt + requirements/ros-jazzy.txt
# VENV overrides the venv path.  Humble and Rolling have no PyPI wheels: build the package
# with colcon on a ROS install instead (docs/node.md, "On a real ROS 2 install").
ROS_DISTRO="${ROS_DISTRO:-kilted}"
case "$ROS_DISTRO" in
    kilted) _default_venv=.venv; RCLPY_DIST=ros-rclpy ;;
    jazzy) _default_venv=.venv-jazzy; RCLPY_DIST=ros-jazzy-rclpy ;;
    *)
        echo "ROS_DISTRO=$ROS_DISTRO: the PyPI ROS 2 wheels exist for kilted and jazzy only" \
             "(on a ROS install use colcon, see docs/node.md)" >&2
        exit 2 ;;
esac
VENV="${VENV:-$_default_venv}"
ROS_REQUIREMENTS="requirements/ros-$ROS_DISTRO.txt"
export ROS_DISTRO VENV
