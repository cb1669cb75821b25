"""Tests of train/losses/anchoring.py: the first-anchor frame and the scale kappa."""

import math

from infinihand_ros.model.pose_encoding import invert_rigid
from infinihand_ros.train.losses import anchor_points
from infinihand_ros.train.losses import anchor_poses
from infinihand_ros.train.losses import sample_scale
from infinihand_ros.train.losses.anchoring import camera_to_world
from loss_builders import rigid
from loss_builders import rotation_x
from loss_builders import rotation_z
import pytest
import torch

#: Dataset-world poses of a two-frame clip: the anchor C_0 and C_1 = C_0 [Rz(0.3) | (3, 4, 0)].
ANCHOR = rigid(rotation_x(0.7), (1.0, 2.0, 3.0))
POSES = torch.stack([ANCHOR, ANCHOR @ rigid(rotation_z(0.3), (3.0, 4.0, 0.0))])[None]


def _to_dataset_world(points_anchor: torch.Tensor) -> torch.Tensor:
    """Return C_0 x of anchor-frame points (..., 3)."""
    return points_anchor @ ANCHOR[:3, :3].T + ANCHOR[:3, 3]


def test_anchor_poses_make_frame_zero_the_identity() -> None:
    """C_0^-1 C_t: identity at the anchor, the relative motion after it."""
    anchored = anchor_poses(POSES)
    torch.testing.assert_close(anchored[0, 0], torch.eye(4, dtype=torch.float64))
    torch.testing.assert_close(anchored[0, 1], rigid(rotation_z(0.3), (3.0, 4.0, 0.0)))
    torch.testing.assert_close(invert_rigid(ANCHOR) @ ANCHOR, torch.eye(4, dtype=torch.float64))


def test_anchor_points_and_camera_to_world() -> None:
    """Dataset-world points come back to the anchor frame; R_t x + u_t moves camera points."""
    points = torch.tensor([[0.3, 0.0, 0.4], [0.0, 0.0, 1.0]], dtype=torch.float64)
    world = _to_dataset_world(points).reshape(1, 2, 1, 3)
    torch.testing.assert_close(anchor_points(world, POSES), points.reshape(1, 2, 1, 3))
    moved = camera_to_world(points.reshape(1, 2, 1, 3), POSES)
    rotation, translation = POSES[0, 1, :3, :3], POSES[0, 1, :3, 3]
    torch.testing.assert_close(moved[0, 1, 0], rotation @ points[1] + translation)


def _joints(norm_frame0: float, norm_frame1: float) -> torch.Tensor:
    """Return dataset-world joints (1, 2, 2, 21, 3) at the given anchor-frame distances."""
    anchored = torch.zeros(1, 2, 2, 21, 3, dtype=torch.float64)
    anchored[0, 0] = torch.tensor([0.6, 0.0, 0.8], dtype=torch.float64) * norm_frame0
    anchored[0, 1] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64) * norm_frame1
    return _to_dataset_world(anchored)


def test_scale_is_the_mean_anchored_joint_distance() -> None:
    """Hand 0 valid at distances 0.5 and 1.0 (hand 1 NaN, invalid): kappa = 0.75."""
    joints = _joints(0.5, 1.0)
    joints[:, :, 1] = float('nan')
    hands = torch.tensor([[[True, False], [True, False]]])
    cameras = torch.tensor([[True, True]])
    kappa = sample_scale(joints, hands, POSES, cameras, 0.1)
    assert kappa.tolist() == pytest.approx([0.75], rel=1e-12)


def test_scale_falls_back_to_camera_centres_then_to_the_floor() -> None:
    """No valid hand: mean anchored centre distance (0 + 5) / 2; no anchor either: the floor."""
    joints = _joints(0.5, 1.0)
    no_hands = torch.zeros(1, 2, 2, dtype=torch.bool)
    kappa = sample_scale(joints, no_hands, POSES, torch.tensor([[True, True]]), 0.1)
    assert kappa.tolist() == pytest.approx([2.5], rel=1e-12)
    hands = torch.ones(1, 2, 2, dtype=torch.bool)
    no_anchor = sample_scale(joints, hands, POSES, torch.tensor([[False, True]]), 0.1)
    assert no_anchor.tolist() == [0.1]
    static = sample_scale(joints, no_hands, POSES[:, :1].expand(1, 2, 4, 4),
                          torch.tensor([[True, True]]), 0.1)
    assert static.tolist() == [0.1]
    assert not math.isnan(sample_scale(torch.full_like(joints, float('nan')), hands,
                                       torch.full_like(POSES, float('nan')),
                                       torch.tensor([[True, True]]), 0.1).item())
