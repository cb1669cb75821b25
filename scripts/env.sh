# Environment of a built infinihand_ros checkout. Source it from the repository root in bash:
#   source scripts/env.sh
# It activates .venv, puts the venv's ROS wheels and the colcon install on AMENT_PREFIX_PATH, the
# package's console scripts on PATH, and keeps DDS discovery on this machine.
_ih_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export VIRTUAL_ENV="${_ih_root}/.venv"
export PATH="${VIRTUAL_ENV}/bin:${PATH}"
case ":${AMENT_PREFIX_PATH:-}:" in
  *":${VIRTUAL_ENV}:"*) ;;
  *) export AMENT_PREFIX_PATH="${VIRTUAL_ENV}${AMENT_PREFIX_PATH:+:${AMENT_PREFIX_PATH}}" ;;
esac
if [ -f "${_ih_root}/install/setup.bash" ]; then
  # shellcheck disable=SC1091
  . "${_ih_root}/install/setup.bash"
fi
# The package's console scripts (bag_to_dataset, replay, ...) by name, as `ros2 run` finds them.
_ih_bin="${_ih_root}/install/infinihand_ros/lib/infinihand_ros"
if [ -d "${_ih_bin}" ]; then
  case ":${PATH}:" in
    *":${_ih_bin}:"*) ;;
    *) export PATH="${_ih_bin}:${PATH}" ;;
  esac
fi
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export FASTRTPS_DEFAULT_PROFILES_FILE="${FASTRTPS_DEFAULT_PROFILES_FILE:-${_ih_root}/config/fastdds_profile.xml}"
export PYTHONDONTWRITEBYTECODE=1
unset _ih_root _ih_bin
