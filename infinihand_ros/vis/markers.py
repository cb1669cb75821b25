"""RViz / Foxglove markers of the hand skeletons and the camera path, as plain descriptions.

Each side has a fixed colour, a ``LINE_LIST`` of its 20 bones and a ``SPHERE_LIST`` of its 21
joints, in the world frame; a hand that is not seen gets DELETE markers for both, so no stale
skeleton stays on screen. The camera path is one ``LINE_STRIP`` of the camera positions.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import JOINT_PARENTS
from infinihand_ros.core.hand_conventions import side_name
from infinihand_ros.core.output_fields import HandOutput
import numpy as np

LINE_LIST: Final = 'line_list'
SPHERE_LIST: Final = 'sphere_list'
LINE_STRIP: Final = 'line_strip'
#: Colours (r, g, b, a in 0..1): left blue, right orange, camera path grey.
SIDE_COLOURS: Final = ((0.12, 0.47, 0.71, 1.0), (1.0, 0.5, 0.05, 1.0))
PATH_COLOUR: Final = (0.6, 0.6, 0.6, 1.0)
#: Line widths and sphere diameters, metres.
BONE_WIDTH_M: Final = 0.004
JOINT_DIAMETER_M: Final = 0.01
PATH_WIDTH_M: Final = 0.01
PATH_NAMESPACE: Final = 'camera_path'
#: (child, parent) joint pairs of the 20 bones.
BONES: Final = tuple((child, parent) for child, parent in enumerate(JOINT_PARENTS) if parent >= 0)


@dataclass(frozen=True)
class MarkerSpec:
    """One visualization_msgs/Marker.

    Attributes:
        namespace: the marker namespace ('left', 'right', 'camera_path').
        marker_id: id within the namespace.
        kind: ``LINE_LIST``, ``SPHERE_LIST`` or ``LINE_STRIP``.
        points: (N, 3) points in the world frame, metres (empty for a deletion).
        rgba: colour, 0..1.
        scale_m: line width or sphere diameter, metres.
        delete: True for a DELETE of this namespace and id.

    """

    namespace: str
    marker_id: int
    kind: str
    points: np.ndarray
    rgba: tuple[float, float, float, float]
    scale_m: float
    delete: bool = False


def hand_markers(side: int, hand: HandOutput | None) -> list[MarkerSpec]:
    """Return the bones and joints markers of ``side``; deletions when ``hand`` is None."""
    namespace, rgba = side_name(side), SIDE_COLOURS[side]
    if hand is None:
        empty = np.zeros((0, 3))
        return [MarkerSpec(namespace, 0, LINE_LIST, empty, rgba, BONE_WIDTH_M, True),
                MarkerSpec(namespace, 1, SPHERE_LIST, empty, rgba, JOINT_DIAMETER_M, True)]
    joints = hand.landmarks_world
    bones = joints[np.array(BONES).reshape(-1)]
    return [MarkerSpec(namespace, 0, LINE_LIST, bones, rgba, BONE_WIDTH_M),
            MarkerSpec(namespace, 1, SPHERE_LIST, joints.copy(), rgba, JOINT_DIAMETER_M)]


def path_marker(positions: np.ndarray) -> MarkerSpec:
    """Return the camera path marker of (N, 3) world positions."""
    return MarkerSpec(PATH_NAMESPACE, 0, LINE_STRIP, np.asarray(positions, dtype=np.float64),
                      PATH_COLOUR, PATH_WIDTH_M)
