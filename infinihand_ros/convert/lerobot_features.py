"""Our LeRobot datasets' features: names, dtypes and per-dimension names, and one frame's values.

The converter (``convert``, ``bag_to_dataset``) writes them and ``data/adapters/lerobot_bags.py``
reads them back, so they are defined here, below both.

Every feature is a flat vector whose ``names`` give each dimension (so the joint order travels
with the data). Per-hand features hold the left hand, then the right one. World-frame values use
the episode's world (the first camera); joints are in OpenPose/MediaPipe order
(``core.hand_conventions.JOINT_NAMES``). A hand is valid when it was detected and placed in the
world; the values of an invalid hand are ``invalid_fill`` and ``hands.valid`` says so.

Only ``observation.state``, ``action`` and the video start with ``observation.``/``action`` so
that LeRobot policies take exactly those as inputs and targets; the other features are data.
``camera.flags`` marks keyframes (frames in the streaming memory), frames whose pose bundle
adjustment corrected, frames whose pose was measured in the image (the per-frame tracker, or a
fixed camera; otherwise the network's motion was used), frames where the camera track
restarted (a discontinuity, e.g. a cut between scenes), keyframes whose last
bundle-adjustment call failed (their poses lack that refinement) and frames whose pose carries
the whole-episode refinement (accepted: it explained held-out tracks better than the stream).
``observation.state`` per hand: wrist position (3), wrist rotation as 6D (the first two columns
of the MANO global orientation matrix, 6), the five fingertips (15).
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import FINGER_JOINTS
from infinihand_ros.core.hand_conventions import FINGER_NAMES
from infinihand_ros.core.hand_conventions import JOINT_NAMES
from infinihand_ros.core.hand_conventions import MANO_JOINT_NAMES
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.core.wrist_frame import keypoints_in_wrist_frame
import numpy as np

STATE: Final = 'observation.state'
ACTION: Final = 'action'
CAMERA_POSE: Final = 'camera.T_world_cam'
INTRINSICS: Final = 'camera.intrinsics'
HAND_VALID: Final = 'hands.valid'
HAND_CONFIDENCE: Final = 'hands.confidence'
WRIST_POSE: Final = 'hands.wrist_pose_world'
KEYPOINTS_WORLD: Final = 'hands.keypoints_world'
KEYPOINTS_WRIST: Final = 'hands.keypoints_wrist'
MANO_GLOBAL_ORIENT: Final = 'hands.mano.global_orient'
MANO_HAND_POSE: Final = 'hands.mano.hand_pose'
MANO_BETAS: Final = 'hands.mano.betas'
CAMERA_FLAGS: Final = 'camera.flags'
CAMERA_FLAG_NAMES: Final = ('keyframe', 'ba_corrected', 'tracked', 'reinitialised',
                            'ba_failed', 'episode_refined')
SOURCE_STAMP: Final = 'source.stamp_ns'
#: LeRobot's bookkeeping columns (shape (1,), no names).
TIMESTAMP: Final = 'timestamp'
FRAME_INDEX: Final = 'frame_index'
EPISODE_INDEX: Final = 'episode_index'
INDEX: Final = 'index'
TASK_INDEX: Final = 'task_index'
DEFAULT_FEATURES: Final = {TIMESTAMP: 'float32', FRAME_INDEX: 'int64', EPISODE_INDEX: 'int64',
                           INDEX: 'int64', TASK_INDEX: 'int64'}

#: A frame is flagged ``ba_corrected`` when BA moved its pose by more than this (m, or rotation
#: matrix entries).
BA_CORRECTED_TOL: Final = 1e-6
XYZ: Final = ('x', 'y', 'z')
NOT_DETECTED: Final = 'not detected'
NOT_IN_WORLD: Final = 'detected but not placed in the world'
DEGENERATE_PALM: Final = 'degenerate palm (no wrist frame)'


@dataclass(frozen=True)
class FeatureSpec:
    """One flat feature: key, dtype ('float32', 'int64' or 'bool') and per-dimension names."""

    key: str
    dtype: str
    names: tuple[str, ...]

    @property
    def shape(self) -> tuple[int]:
        """Return ``(len(names),)``."""
        return (len(self.names),)


def _per_side(names: list[str]) -> tuple[str, ...]:
    return tuple(f'{side}_{name}' for side in SIDE_NAMES for name in names)


def _points(joints: tuple[str, ...]) -> list[str]:
    return [f'{joint}_{axis}' for joint in joints for axis in XYZ]


TIP_JOINTS: Final = tuple(joints[-1] for joints in FINGER_JOINTS)
STATE_NAMES: Final = _per_side(
    [f'wrist_{axis}' for axis in XYZ] + [f'wrist_rot6d_{i}' for i in range(6)]
    + _points(tuple(f'{finger}_tip' for finger in FINGER_NAMES)))

#: The per-frame features, in column order.
FRAME_FEATURES: Final = (
    FeatureSpec(STATE, 'float32', STATE_NAMES),
    FeatureSpec(ACTION, 'float32', STATE_NAMES),
    FeatureSpec(CAMERA_POSE, 'float32',
                tuple(f'T_world_cam_{row}{col}' for row in range(4) for col in range(4))),
    FeatureSpec(INTRINSICS, 'float32', ('fx', 'fy', 'cx', 'cy')),
    FeatureSpec(CAMERA_FLAGS, 'bool', CAMERA_FLAG_NAMES),
    FeatureSpec(HAND_VALID, 'bool', SIDE_NAMES),
    FeatureSpec(HAND_CONFIDENCE, 'float32', SIDE_NAMES),
    FeatureSpec(WRIST_POSE, 'float32', _per_side(
        [f'wrist_{axis}' for axis in XYZ] + [f'wrist_q{axis}' for axis in XYZ + ('w',)])),
    FeatureSpec(KEYPOINTS_WORLD, 'float32', _per_side(_points(JOINT_NAMES))),
    FeatureSpec(KEYPOINTS_WRIST, 'float32', _per_side(_points(JOINT_NAMES))),
    FeatureSpec(MANO_GLOBAL_ORIENT, 'float32', _per_side(_points(('global_orient',)))),
    FeatureSpec(MANO_HAND_POSE, 'float32', _per_side(_points(MANO_JOINT_NAMES[1:]))),
    FeatureSpec(MANO_BETAS, 'float32', _per_side([f'beta_{i}' for i in range(NUM_BETAS)])),
    FeatureSpec(SOURCE_STAMP, 'int64', ('stamp_ns',)),
)
#: Features with a left and a right half, filled from each hand.
HAND_FEATURES: Final = (STATE, HAND_VALID, HAND_CONFIDENCE, WRIST_POSE, KEYPOINTS_WORLD,
                        KEYPOINTS_WRIST, MANO_GLOBAL_ORIENT, MANO_HAND_POSE, MANO_BETAS)
#: Features filled from one engine result (all but ``action`` and the source stamp).
RESULT_FEATURES: Final = HAND_FEATURES + (CAMERA_POSE, INTRINSICS, CAMERA_FLAGS)


def _hand_values(hand: HandState) -> dict[str, np.ndarray]:
    """Return one valid hand's part of each per-hand feature (float64)."""
    rotation = geometry.axis_angle_to_matrix(hand.mano_world.global_orient)
    joints = hand.joints_world
    wrist_keypoints, _ = keypoints_in_wrist_frame(joints, hand.side)
    return {
        STATE: np.concatenate([joints[WRIST], rotation[:, :2].T.reshape(-1),
                               joints[list(TIP_JOINTS)].reshape(-1)]),
        HAND_VALID: np.ones(1),
        HAND_CONFIDENCE: np.array([hand.confidence]),
        WRIST_POSE: np.concatenate([joints[WRIST], geometry.matrix_to_quaternion_xyzw(rotation)]),
        KEYPOINTS_WORLD: joints.reshape(-1),
        KEYPOINTS_WRIST: wrist_keypoints.reshape(-1),
        MANO_GLOBAL_ORIENT: hand.mano_world.global_orient,
        MANO_HAND_POSE: hand.mano_world.hand_pose.reshape(-1),
        MANO_BETAS: hand.mano_world.betas,
    }


def _hand_or_reason(hand: HandState | None) -> dict[str, np.ndarray] | str:
    if hand is None:
        return NOT_DETECTED
    if hand.mano_world is None or hand.joints_world is None:
        return NOT_IN_WORLD
    try:
        return _hand_values(hand)
    except InputError:
        return DEGENERATE_PALM


def _invalid_values(hand: HandState | None, fill: float) -> dict[str, np.ndarray]:
    """Return an invalid hand's part of each per-hand feature (its confidence is kept)."""
    values = {spec.key: np.full(spec.shape[0] // len(SIDES), fill)
              for spec in FRAME_FEATURES if spec.key in HAND_FEATURES}
    values[HAND_VALID] = np.zeros(1)
    values[HAND_CONFIDENCE] = np.array([0.0 if hand is None else hand.confidence])
    return values


def frame_values(result: FrameResult, fill: float) -> tuple[dict[str, np.ndarray],
                                                            dict[str, str]]:
    """Return one result's values of ``RESULT_FEATURES`` and why any hand is invalid.

    Args:
        result: the engine's result for the frame.
        fill: value of the features of an invalid hand (``hands.valid`` is False).

    Returns:
        (feature key -> 1-D float64 vector, side name -> reason for each invalid hand).

    """
    halves: list[dict[str, np.ndarray]] = []
    reasons: dict[str, str] = {}
    for side in SIDES:
        hand = result.hand(side)
        values = _hand_or_reason(hand)
        if isinstance(values, str):
            reasons[SIDE_NAMES[side]] = values
            values = _invalid_values(hand, fill)
        halves.append(values)
    out = {key: np.concatenate([half[key] for half in halves]) for key in HAND_FEATURES}
    out[CAMERA_POSE] = result.camera_pose.matrix().reshape(-1)
    intrinsics = result.intrinsics
    out[INTRINSICS] = np.array([intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy])
    raw = result.raw_camera_pose
    corrected = raw is not None and not np.allclose(raw.matrix(), result.camera_pose.matrix(),
                                                    atol=BA_CORRECTED_TOL)
    out[CAMERA_FLAGS] = np.array([result.is_keyframe, corrected,
                                  result.tracking in ('tracked', 'static'),
                                  result.tracking == 'reinitialised', result.ba_failed,
                                  result.episode_refined],
                                 dtype=np.float64)
    return out, reasons
