#!/usr/bin/env bash
# Print the interface packages colcon builds beside infinihand_ros (its --base-paths):
# msg_schemas (infinihand_msgs) always, and msg_schemas/tf2_msgs (tf2_msgs/msg/TFMessage) only where
# no installed ROS 2 on AMENT_PREFIX_PATH (other than this checkout's install/) provides tf2_msgs.
_ih_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_ih_paths="msg_schemas msg_schemas/tf2_msgs"
IFS=: read -r -a _ih_prefixes <<< "${AMENT_PREFIX_PATH:-}"
for _ih_prefix in "${_ih_prefixes[@]}"; do
  case "${_ih_prefix}" in
    "${_ih_root}/install"*) ;;
    *) if [ -e "${_ih_prefix}/share/ament_index/resource_index/packages/tf2_msgs" ]; then
         _ih_paths="msg_schemas"
       fi ;;
  esac
done
echo "${_ih_paths}"
