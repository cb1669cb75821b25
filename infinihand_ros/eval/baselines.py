"""The evaluation's baselines, computed beside our predictions on the same hand-frame pairs.

- ``static-camera``: our camera-space hands, but the camera held at its first-frame pose
  (what a pipeline without camera tracking would output);
- ``mean-hand``: per side, the mean ground-truth world joints over the sequence: one constant
  skeleton that never moves (what "knowing roughly where the hands are" scores);
- ``mean-pose``: the training set's mean articulation (built-in hand, mean shape), for
  PA-MPJPE: what knowing only the average finger pose scores once position, orientation and
  scale are aligned away.

The mean articulation is the per-joint rotation mean (``scipy`` ``Rotation.mean``) of the
right-hand-canonical local joint rotations, left hands mirrored onto the right first.
"""

from collections.abc import Sequence

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.mirror import mirror_axis_angle
import numpy as np
from scipy.spatial.transform import Rotation
import torch

#: Names of the baselines, in report order.
BASELINES = ('static-camera', 'mean-hand', 'mean-pose')


def mean_articulation(hand_poses: Sequence[np.ndarray], sides: Sequence[int]) -> np.ndarray:
    """Return the mean right-hand articulation (15, 3) of hand poses (N_i, 15, 3) per side.

    Raises:
        InputError: when no pose is given.

    """
    rights = [mirror_axis_angle(np.asarray(pose, dtype=np.float64)) if side == LEFT
              else np.asarray(pose, dtype=np.float64)
              for pose, side in zip(hand_poses, sides) if len(pose)]
    if not rights:
        raise InputError('mean articulation: no hand pose given')
    stacked = np.concatenate(rights).reshape(-1, NUM_HAND_POSE_JOINTS, 3)
    return np.stack([Rotation.from_rotvec(stacked[:, joint]).mean().as_rotvec()
                     for joint in range(NUM_HAND_POSE_JOINTS)])


def mean_pose_joints(mean_right_pose: np.ndarray, betas: np.ndarray | None = None
                     ) -> np.ndarray:
    """Return (2, 21, 3) joints of the mean articulation per side (zero orientation, at 0)."""
    pose = np.asarray(mean_right_pose, dtype=np.float64).reshape(NUM_HAND_POSE_JOINTS, 3)
    shape = np.zeros(NUM_BETAS) if betas is None else np.asarray(betas, dtype=np.float64)
    joints = []
    for side in SIDES:
        side_pose = mirror_axis_angle(pose) if side == LEFT else pose
        model = BuiltinHandModel(side, dtype=torch.float64)
        with torch.no_grad():
            out = model(torch.zeros(1, 3, dtype=torch.float64),
                        torch.as_tensor(side_pose)[None], torch.as_tensor(shape)[None],
                        torch.zeros(1, 3, dtype=torch.float64))
        joints.append(out.joints[0].numpy())
    return np.stack(joints)


def static_camera_joints(joints_cam: np.ndarray, first_T_world_cam: np.ndarray) -> np.ndarray:
    """Return world joints (T, 2, 21, 3) of camera-space joints with the first frame's camera."""
    rotation, translation = first_T_world_cam[:3, :3], first_T_world_cam[:3, 3]
    return joints_cam @ rotation.T + translation


def mean_hand_joints(gt_joints_world: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Return (T, 2, 21, 3): per side the mean of the valid ground-truth world joints, repeated.

    A side without a valid frame is NaN (and has no pair to be scored on).
    """
    out = np.full_like(np.asarray(gt_joints_world, dtype=np.float64), np.nan)
    for side in SIDES:
        rows = valid[:, side]
        if rows.any():
            out[:, side] = gt_joints_world[rows, side].mean(axis=0)
    return out


def mean_pose_world_joints(mean_joints: np.ndarray, num_frames: int) -> np.ndarray:
    """Return (T, 2, 21, 3) repeating the mean-pose skeletons (PA-MPJPE aligns each pair)."""
    if mean_joints.shape != (len(SIDES), NUM_JOINTS, 3):
        raise InputError(f'mean-pose joints: expected (2, 21, 3), got {mean_joints.shape}')
    return np.broadcast_to(mean_joints, (num_frames, *mean_joints.shape)).copy()
