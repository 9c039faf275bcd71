# Environment of the suite: source it (`. scripts/env.sh`) to get ROS 2, the venv and the built
# workspace on PATH, exactly as `make` uses them. Safe to source more than once.
_ato_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_ato_venv="${ATO_VENV:-$_ato_root/.venv}"

if [ -f /opt/ros/jazzy/setup.bash ]; then
  # A real Jazzy install provides rclpy and the messages; the venv only adds numpy, mcap, colcon...
  set +u; . /opt/ros/jazzy/setup.bash; set -u 2>/dev/null || true
fi
if [ -f "$_ato_venv/bin/activate" ]; then
  . "$_ato_venv/bin/activate"
  # The Jazzy PyPI wheels install their ament index under the venv prefix.
  case ":${AMENT_PREFIX_PATH:-}:" in
    *":$_ato_venv:"*) ;;
    *) export AMENT_PREFIX_PATH="$_ato_venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
  esac
fi
if [ -f "$_ato_root/ros_ws/install/setup.bash" ]; then
  set +u; . "$_ato_root/ros_ws/install/setup.bash"; set -u 2>/dev/null || true
fi
# The repository's tooling (tools/ato_tools: the docs' reference pages, the reproduction page):
# not a package of the suite, importable from the repository.
case ":${PYTHONPATH:-}:" in
  *":$_ato_root/tools:"*) ;;
  *) export PYTHONPATH="$_ato_root/tools${PYTHONPATH:+:$PYTHONPATH}" ;;
esac
# The suite's command line (scripts/bin/ato: ato run, ato launch, ato param, ...), which takes the
# arguments of the ros2 commands the docs show: the wheels have no ros2.
case ":${PATH}:" in
  *":$_ato_root/scripts/bin:"*) ;;
  *) export PATH="$_ato_root/scripts/bin:$PATH" ;;
esac
# Keep DDS traffic on this machine unless the user asked otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
unset _ato_root _ato_venv
