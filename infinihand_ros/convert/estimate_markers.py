"""Foxglove / RViz markers of the bag of estimates: hand skeletons and the camera path.

The content is the estimator node's (``vis.markers``: left blue, right orange, the 20 bones as a
``LINE_LIST`` and the 21 joints as a ``SPHERE_LIST`` per hand, DELETE markers for a hand not
placed in the world, the camera path as a grey ``LINE_STRIP``), so a converted episode and a live
run look the same. ``vis.markers`` and ``vis.output_fields`` are plain numpy (no rclpy); this
module turns their descriptions into rosbags ``visualization_msgs/msg/MarkerArray`` messages.
"""

from collections import deque
from typing import Any, Final

from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import POINT_MSG
from infinihand_ros.bag.typestore import POSE_MSG
from infinihand_ros.bag.typestore import QUATERNION_MSG
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.vis.markers import hand_markers
from infinihand_ros.vis.markers import LINE_LIST
from infinihand_ros.vis.markers import LINE_STRIP
from infinihand_ros.vis.markers import MarkerSpec
from infinihand_ros.vis.markers import path_marker
from infinihand_ros.vis.markers import SPHERE_LIST
import numpy as np
from rosbags.typesys.store import Typestore

MARKER_MSG: Final = 'visualization_msgs/msg/Marker'
MARKER_ARRAY_MSG: Final = 'visualization_msgs/msg/MarkerArray'
MESH_FILE_MSG: Final = 'visualization_msgs/msg/MeshFile'
COLOR_MSG: Final = 'std_msgs/msg/ColorRGBA'
VECTOR3_MSG: Final = 'geometry_msgs/msg/Vector3'
DURATION_MSG: Final = 'builtin_interfaces/msg/Duration'
#: MarkerSpec kind -> the Marker ``type`` constant's name.
MARKER_TYPES: Final = {LINE_LIST: 'LINE_LIST', SPHERE_LIST: 'SPHERE_LIST',
                       LINE_STRIP: 'LINE_STRIP'}


class CameraPathPoints:
    """The newest ``capacity`` camera positions of an episode, oldest first."""

    def __init__(self, capacity: int) -> None:
        """Start an empty path that keeps at most ``capacity`` positions."""
        self._positions: deque[np.ndarray] = deque(maxlen=capacity)

    def add(self, position: np.ndarray) -> np.ndarray:
        """Append a (3,) world position (metres); return the path as (N, 3) float64."""
        self._positions.append(np.asarray(position, dtype=np.float64))
        return np.stack(self._positions)


def frame_marker_specs(result: FrameResult, path: np.ndarray) -> list[MarkerSpec]:
    """Return the markers of one frame: both hands (left, right), then the camera path.

    Args:
        result: the engine's result; a hand without world joints (or a degenerate palm) gets
            DELETE markers, as in the node.
        path: (N, 3) camera positions in the world frame up to this frame, metres.

    """
    specs: list[MarkerSpec] = []
    for side in SIDES:
        hand = result.hand(side)
        specs += hand_markers(side, None if hand is None else hand_output(hand))
    specs.append(path_marker(path))
    return specs


def _marker_msg(store: Typestore, header: Any, spec: MarkerSpec) -> Any:
    """Return one rosbags Marker (every unused field empty)."""
    marker = store.types[MARKER_MSG]
    types = store.types
    r, g, b, a = (float(value) for value in spec.rgba)
    scale = float(spec.scale_m)
    return marker(
        header=header, ns=spec.namespace, id=spec.marker_id,
        type=getattr(marker, MARKER_TYPES[spec.kind]),
        action=marker.DELETE if spec.delete else marker.ADD,
        pose=types[POSE_MSG](position=types[POINT_MSG](x=0.0, y=0.0, z=0.0),
                             orientation=types[QUATERNION_MSG](x=0.0, y=0.0, z=0.0, w=1.0)),
        scale=types[VECTOR3_MSG](x=scale, y=scale, z=scale),
        color=types[COLOR_MSG](r=r, g=g, b=b, a=a),
        lifetime=types[DURATION_MSG](sec=0, nanosec=0), frame_locked=False,
        points=[types[POINT_MSG](x=float(x), y=float(y), z=float(z)) for x, y, z in spec.points],
        colors=[], texture_resource='',
        texture=types[COMPRESSED_IMAGE_MSG](header=header, format='',
                                            data=np.zeros(0, dtype=np.uint8)),
        uv_coordinates=[], text='', mesh_resource='',
        mesh_file=types[MESH_FILE_MSG](filename='', data=np.zeros(0, dtype=np.uint8)),
        mesh_use_embedded_materials=False)


def marker_array_msg(store: Typestore, stamp_ns: int, frame_id: str,
                     specs: list[MarkerSpec]) -> Any:
    """Return a rosbags ``visualization_msgs/msg/MarkerArray`` of the descriptions.

    Args:
        store: a typestore of ``bag.typestore.build_typestore()`` (ROS 2 Jazzy types).
        stamp_ns: header stamp of every marker (the source image's), nanoseconds.
        frame_id: the frame of the points (the world frame).
        specs: the markers.

    """
    header = store.types[HEADER_MSG](stamp=stamp_from_ns(store, stamp_ns), frame_id=frame_id)
    return store.types[MARKER_ARRAY_MSG](
        markers=[_marker_msg(store, header, spec) for spec in specs])
