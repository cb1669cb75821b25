"""The wrist frame that dex-retargeting and the Vision-Pro/Quest teleop stacks expect.

Those consumers take the 21 keypoints (MediaPipe order) root-relative and expressed in a wrist
frame estimated from the wrist, index MCP and middle MCP (joints 0, 5, 9), then mapped by a fixed
operator-to-MANO axis permutation per side:

- x: from the middle MCP towards the wrist, projected onto the palm plane;
- y: the palm-plane normal (the plane of joints 0, 5, 9, fitted by SVD);
- z: x cross y, flipped together with y so that it points from the middle MCP to the index MCP.

``keypoints_in_wrist_frame = (joints - joints[0]) @ frame @ OPERATOR_TO_MANO[side]``.
"""

from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import side_name
from infinihand_ros.core.hand_conventions import WRIST_FRAME_JOINTS
from infinihand_ros.core.validation import as_array
import numpy as np

#: Axis maps from the estimated wrist frame to MANO's hand axes, per side (dex-retargeting).
OPERATOR_TO_MANO: Final = {
    RIGHT: np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    LEFT: np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
}


def estimate_wrist_frame(joints: np.ndarray) -> np.ndarray:
    """Estimate the wrist frame from 21 joints (any frame, metres).

    Args:
        joints: (21, 3) joints in OpenPose/MediaPipe order.

    Returns:
        (3, 3) rotation whose columns are the frame's x, y (palm normal) and z axes.

    Raises:
        InputError: for a wrong shape, NaN, or degenerate palm joints.

    """
    pts = as_array(joints, 'hand joints', (NUM_JOINTS, 3))
    palm = pts[list(WRIST_FRAME_JOINTS)] - pts[0]
    wrist, index_mcp, middle_mcp = palm
    x_vector = wrist - middle_mcp
    centered = palm - palm.mean(axis=0, keepdims=True)
    _, singular_values, vh = np.linalg.svd(centered)
    if singular_values[1] < 1e-9:
        raise InputError('hand joints: wrist, index MCP and middle MCP are collinear or equal; '
                         'cannot estimate a wrist frame')
    normal = vh[2]
    x_axis = x_vector - np.dot(x_vector, normal) * normal
    x_axis /= np.linalg.norm(x_axis)
    z_axis = np.cross(x_axis, normal)
    if np.dot(z_axis, index_mcp - middle_mcp) < 0:
        normal, z_axis = -normal, -z_axis
    return np.stack([x_axis, normal, z_axis], axis=1)


def keypoints_in_wrist_frame(joints: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray]:
    """Return dex-retargeting input: root-relative keypoints in the MANO-aligned wrist frame.

    Args:
        joints: (21, 3) joints in OpenPose/MediaPipe order (any frame, metres).
        side: 0 left, 1 right.

    Returns:
        (keypoints (21, 3) in the wrist frame, wrist_rotation (3, 3)) where
        ``wrist_rotation = frame @ OPERATOR_TO_MANO[side]`` maps wrist-frame vectors back into the
        input frame (its columns are the wrist frame's axes there).

    """
    side_name(side)
    pts = as_array(joints, 'hand joints', (NUM_JOINTS, 3))
    wrist_rotation = estimate_wrist_frame(pts) @ OPERATOR_TO_MANO[side]
    return (pts - pts[0]) @ wrist_rotation, wrist_rotation
