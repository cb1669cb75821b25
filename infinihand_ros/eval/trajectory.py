"""Camera-trajectory metrics: ATE after a similarity alignment and RPE over consecutive frames.

ATE (absolute trajectory error, metres) is the RMS distance between the ground-truth camera
centres and the predicted ones after the best proper similarity (Umeyama: scale, rotation,
translation) maps the predicted centres onto the ground truth. RPE (relative pose error) compares
the motion between frames i and i + delta: its translation part is the RMS norm of the
difference of the relative translations (the prediction scaled by the ATE's scale, metres), its
rotation part the mean angle of the relative rotations' difference (degrees).
"""

from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import apply_similarity
from infinihand_ros.core.geometry import invert_transform
from infinihand_ros.core.geometry import rotation_angle_deg
from infinihand_ros.core.geometry import similarity_transform
from infinihand_ros.core.validation import as_array
import numpy as np

#: Trajectories whose centres spread less than this (m^2, mean squared) have no defined
#: alignment scale: the predicted centres are mapped onto the ground-truth centroid.
_MIN_SPREAD_M2 = 1e-18


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Camera-trajectory errors of one sequence.

    Attributes:
        ate_m: absolute trajectory error after similarity alignment (m, RMS).
        rpe_translation_m: relative translation error over ``delta`` frames (m, RMS).
        rpe_rotation_deg: relative rotation error over ``delta`` frames (degrees, mean).
        scale: the alignment's scale (ground-truth metres per predicted unit).
        num_frames: frames compared.

    """

    ate_m: float
    rpe_translation_m: float
    rpe_rotation_deg: float
    scale: float
    num_frames: int

    def as_dict(self) -> dict[str, float]:
        """Return the metrics under their report names (ATE, RPE-t, RPE-r)."""
        return {'ATE': self.ate_m, 'RPE-t': self.rpe_translation_m,
                'RPE-r': self.rpe_rotation_deg}


def trajectory_metrics(pred_T_world_cam: np.ndarray, gt_T_world_cam: np.ndarray,
                       delta: int = 1) -> TrajectoryMetrics:
    """Return ATE and RPE of predicted against ground-truth camera-to-world poses (T, 4, 4).

    Raises:
        InputError: for mismatched shapes, non-finite poses, fewer than ``delta + 1`` frames.

    """
    pred = as_array(pred_T_world_cam, 'pred_T_world_cam', (None, 4, 4))
    gt = as_array(gt_T_world_cam, 'gt_T_world_cam', (pred.shape[0], 4, 4))
    if delta < 1 or pred.shape[0] <= delta:
        raise InputError(f'trajectory metrics need more than delta = {delta} frames '
                         f'(>= 1), got {pred.shape[0]}')
    pred_centres, gt_centres = pred[:, :3, 3], gt[:, :3, 3]
    spread = np.square(pred_centres - pred_centres.mean(axis=0)).sum(axis=-1).mean()
    if spread < _MIN_SPREAD_M2:
        scale = 1.0
        aligned = np.broadcast_to(gt_centres.mean(axis=0), gt_centres.shape)
    else:
        s, rotation, translation = similarity_transform(pred_centres, gt_centres)
        scale = float(s)
        aligned = apply_similarity(pred_centres, s, rotation, translation)
    ate = float(np.sqrt(np.square(aligned - gt_centres).sum(axis=-1).mean()))
    pred_rel = invert_transform(pred[:-delta]) @ pred[delta:]
    gt_rel = invert_transform(gt[:-delta]) @ gt[delta:]
    translation_error = scale * pred_rel[:, :3, 3] - gt_rel[:, :3, 3]
    return TrajectoryMetrics(
        ate_m=ate,
        rpe_translation_m=float(np.sqrt(np.square(translation_error).sum(axis=-1).mean())),
        rpe_rotation_deg=float(rotation_angle_deg(pred_rel[:, :3, :3], gt_rel[:, :3, :3]).mean()),
        scale=scale, num_frames=int(pred.shape[0]))
