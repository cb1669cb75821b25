"""The anchor transformation and the sample-level normalisation kappa (paper Sec. 3.3).

World-space supervision is expressed in the first-anchor world frame: the camera of frame 0 of
the clip. Predictions already live there (the camera head's world is its first anchor camera),
so only targets are moved: a target pose ``C_t`` (camera-to-world in the dataset's world)
becomes ``C_0^-1 C_t`` and a target world point ``x`` becomes ``C_0^-1 x``; a clip whose
frame-0 camera annotation is missing has no anchor, and its world-space targets leave the valid
set. Both sides are then divided by the sample's scale kappa > 0.

The paper does not define kappa; like VGGT's normalisation (mean distance of the valid
ground-truth points from the first camera) we take the mean Euclidean distance of the sample's
valid anchored target world joints from the anchor camera centre; a sample with no valid joint
uses the mean distance of its valid anchored target camera centres instead, and kappa is
floored at ``min_scale_m`` (so a static camera or an empty sample gives the floor, not 0).
kappa comes from targets only and carries no gradient.
"""

from infinihand_ros.model.pose_encoding import invert_rigid
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import finite_rows
import torch


def anchor_poses(T_world_cam: torch.Tensor) -> torch.Tensor:
    """Return ``T_anchor_cam = C_0^-1 C_t`` (B, S, 4, 4) of camera-to-world poses (B, S, 4, 4).

    Non-finite poses are read as zeros first, so the result is finite everywhere (garbage, but
    finite, where the pose or the anchor was not).
    """
    poses = finite_or_zero(T_world_cam)
    return invert_rigid(poses[:, :1]) @ poses


def anchor_valid(camera_valid: torch.Tensor, T_world_cam: torch.Tensor) -> torch.Tensor:
    """Return (B,) bool: the clip's frame-0 camera is annotated and finite."""
    return camera_valid[:, 0] & finite_rows(T_world_cam[:, 0], dims=2)


def anchor_points(points_world: torch.Tensor, T_world_cam: torch.Tensor) -> torch.Tensor:
    """Move target points into the first-anchor frame.

    Args:
        points_world: (B, S, ..., 3) points in the dataset's world frame.
        T_world_cam: (B, S, 4, 4) target camera-to-world poses (only frame 0 is used).

    Returns:
        (B, S, ..., 3) ``C_0^-1 x``; non-finite inputs are read as zeros.

    """
    anchor = invert_rigid(finite_or_zero(T_world_cam[:, 0]))
    extra = points_world.ndim - 3
    rotation = anchor[:, :3, :3].reshape(anchor.shape[0], *([1] * (extra + 1)), 3, 3)
    offset = anchor[:, :3, 3].reshape(anchor.shape[0], *([1] * (extra + 1)), 3)
    return (rotation @ finite_or_zero(points_world)[..., None])[..., 0] + offset


def camera_to_world(points_cam: torch.Tensor, T_world_cam: torch.Tensor) -> torch.Tensor:
    """Return ``R_t x + u_t`` (B, S, ..., 3) of camera-frame points and poses (B, S, 4, 4)."""
    extra = points_cam.ndim - 3
    shape = (*T_world_cam.shape[:2], *([1] * extra))
    rotation = T_world_cam[..., :3, :3].reshape(*shape, 3, 3)
    offset = T_world_cam[..., :3, 3].reshape(*shape, 3)
    return (rotation @ points_cam[..., None])[..., 0] + offset


@torch.no_grad()
def sample_scale(target_joints_world: torch.Tensor, hand_valid: torch.Tensor,
                 target_T_world_cam: torch.Tensor, camera_valid: torch.Tensor,
                 min_scale_m: float) -> torch.Tensor:
    """Return kappa (B,) of each sample, from its targets (see the module docstring).

    Args:
        target_joints_world: (B, S, 2, 21, 3) target world joints (dataset world frame, m).
        hand_valid: (B, S, 2) bool, the hand's joint annotation exists.
        target_T_world_cam: (B, S, 4, 4) target camera-to-world poses.
        camera_valid: (B, S) bool, the frame's camera annotation exists.
        min_scale_m: floor of kappa (m).

    Returns:
        (B,) kappa in metres, >= ``min_scale_m``, no gradient.

    """
    has_anchor = anchor_valid(camera_valid, target_T_world_cam)
    joints = anchor_points(target_joints_world, target_T_world_cam)
    joint_ok = (hand_valid[..., None] & finite_rows(target_joints_world)
                & has_anchor[:, None, None, None])
    centres = anchor_poses(target_T_world_cam)[..., :3, 3]
    centre_ok = camera_valid & finite_rows(target_T_world_cam, dims=2) & has_anchor[:, None]
    joint_mean, joint_count = _mean_norm(joints, joint_ok)
    centre_mean, _ = _mean_norm(centres, centre_ok)
    scale = torch.where(joint_count > 0, joint_mean, centre_mean)
    return scale.clamp(min=min_scale_m)


def _mean_norm(points: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Return the per-sample mean norm (B,) of the valid points (B, ..., 3) and their count."""
    norms = torch.where(valid, torch.linalg.vector_norm(points, dim=-1),
                        torch.zeros_like(valid, dtype=points.dtype))
    count = valid.flatten(1).sum(dim=1)
    return norms.flatten(1).sum(dim=1) / count.clamp(min=1).to(points.dtype), count
