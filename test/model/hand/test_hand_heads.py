"""MANO head (6D decoding, start at the coarse hand), 2D head and the geometric adapter."""

from infinihand_ros.core import geometry
from infinihand_ros.model.hand.adapter import appearance_patch_centres
from infinihand_ros.model.hand.adapter import GeometricAdapter
from infinihand_ros.model.hand.appearance_vit import IDENTITY_6D
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.crop_camera import apply_homography
from infinihand_ros.model.hand.crop_camera import build_crop_cameras
from infinihand_ros.model.hand.crop_camera import sample_at_crop_pixels
from infinihand_ros.model.hand.landmark_head import LandmarkHead
from infinihand_ros.model.hand.mano_head import ManoHead
from infinihand_ros.model.hand.mano_head import rotation_6d_to_matrix
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
import torch

TINY = load_hand_branch_config('tiny')


def test_6d_is_the_first_two_columns() -> None:
    rotations = torch.as_tensor(Rotation.random(5, random_state=2).as_matrix())
    six = torch.cat([rotations[..., 0], rotations[..., 1]], dim=-1)
    np.testing.assert_allclose(rotation_6d_to_matrix(six).numpy(), rotations.numpy(), atol=1e-12)
    identity = rotation_6d_to_matrix(torch.tensor(IDENTITY_6D, dtype=torch.float64))
    np.testing.assert_allclose(identity.numpy(), np.eye(3), atol=1e-15)


def test_mano_head_starts_at_the_coarse_hand(rng: np.random.Generator) -> None:
    torch.manual_seed(0)
    head = ManoHead(TINY).double()
    grid_h, grid_w = TINY.appearance.grid_size
    fused = torch.as_tensor(rng.normal(size=(3, TINY.fusion_dim, grid_h, grid_w)))
    rotations = Rotation.random(3 * 16, random_state=3).as_matrix().reshape(3, 16, 3, 3)
    coarse_6d = torch.as_tensor(np.concatenate([rotations[..., 0], rotations[..., 1]], -1))
    coarse_betas = torch.as_tensor(rng.normal(size=(3, 10)))
    prior = torch.as_tensor(rng.normal(size=3))
    with torch.no_grad():
        out = head(fused, coarse_6d, coarse_betas, prior)
    assert out.hand_pose.shape == (3, 15, 3) and out.global_orient.shape == (3, 3)
    got = geometry.axis_angle_to_matrix(
        torch.cat([out.global_orient[:, None], out.hand_pose], dim=1).numpy())
    angle = geometry.rotation_angle_deg(got, rotations)
    assert angle.max() < 5.0  # degrees: small residuals at initialisation
    np.testing.assert_allclose(out.betas.numpy(), coarse_betas.numpy(), atol=0.2)
    np.testing.assert_allclose(out.log_depth.numpy(), prior.numpy(), atol=0.2)


def test_landmark_head_shapes_and_range(rng: np.random.Generator) -> None:
    torch.manual_seed(0)
    head = LandmarkHead(TINY)
    grid_h, grid_w = TINY.appearance.grid_size
    fused = torch.as_tensor(rng.normal(size=(4, TINY.fusion_dim, grid_h, grid_w)),
                            dtype=torch.float32)
    landmarks, confidence = head(fused)
    assert landmarks.shape == (4, 21, 2) and confidence.shape == (4,)
    assert ((confidence > 0) & (confidence < 1)).all()


def test_patch_centres_are_the_vit_windows() -> None:
    centres = appearance_patch_centres(TINY)
    grid_h, grid_w = TINY.appearance.grid_size
    assert centres.shape == (grid_h * grid_w, 2)
    # Tiny: the 96-wide window starts at column 16; the padded 16-px kernel of patch (0, 0)
    # covers columns 14..29 and rows -2..13, centred at (21.5, 5.5); steps of 16 px.
    np.testing.assert_allclose(centres[0].numpy(), [21.5, 5.5])
    np.testing.assert_allclose(centres[grid_w + 1].numpy(), [37.5, 21.5])


@pytest.mark.parametrize('flipped', [False, True])
def test_adapter_samples_features_at_the_warped_patch_centres(flipped: bool) -> None:
    """Features holding their cell-centre pixel coordinates read back the mapped centres."""
    patch, grid_h, grid_w = 14, 12, 16
    rows = torch.arange(grid_h, dtype=torch.float64) * patch + (patch - 1) / 2.0
    cols = torch.arange(grid_w, dtype=torch.float64) * patch + (patch - 1) / 2.0
    v, u = torch.meshgrid(rows, cols, indexing='ij')
    features = torch.stack([u, v])[None]
    k = torch.tensor([[[150.0, 0.0, 112.0], [0.0, 150.0, 84.0], [0.0, 0.0, 1.0]]],
                     dtype=torch.float64)
    box = torch.tensor([[90.0, 60.0, 130.0, 100.0]], dtype=torch.float64)
    cameras = build_crop_cameras(box, k, torch.tensor([flipped]), TINY.crop_size,
                                 TINY.box_expansion)
    centres = appearance_patch_centres(TINY)
    sampled = sample_at_crop_pixels(features, torch.zeros(1, dtype=torch.long), cameras,
                                    centres, (grid_h * patch, grid_w * patch))
    expected = apply_homography(cameras.crop_to_image_homography(), centres[None])
    np.testing.assert_allclose(sampled[0].T.numpy(), expected[0].numpy(), atol=1e-9)


def test_adapter_output_grid(rng: np.random.Generator) -> None:
    torch.manual_seed(0)
    adapter = GeometricAdapter(TINY, feature_dim=32).double()
    k = torch.tensor([[[150.0, 0.0, 112.0], [0.0, 150.0, 84.0], [0.0, 0.0, 1.0]]],
                     dtype=torch.float64).expand(2, 3, 3)
    boxes = torch.tensor([[90.0, 60.0, 130.0, 100.0], [10.0, 10.0, 40.0, 50.0]],
                         dtype=torch.float64)
    cameras = build_crop_cameras(boxes, k, torch.tensor([False, True]), TINY.crop_size, 1.5)
    features = torch.as_tensor(rng.normal(size=(1, 32, 12, 16)))
    out = adapter(features, torch.zeros(2, dtype=torch.long), cameras, (168, 224))
    assert out.shape == (2, TINY.adapter_dim, *TINY.appearance.grid_size)
    assert torch.isfinite(out).all()
