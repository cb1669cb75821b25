"""Crop cameras and warps: projections agree with the warped pixels; flips are exact mirrors."""

from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
from infinihand_ros.model.hand.crop_camera import apply_homography
from infinihand_ros.model.hand.crop_camera import build_crop_cameras
from infinihand_ros.model.hand.crop_camera import flip_normalized
from infinihand_ros.model.hand.crop_camera import normalized_to_pixels
from infinihand_ros.model.hand.crop_camera import pixels_to_normalized
from infinihand_ros.model.hand.crop_camera import warp_to_crop
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np
import pytest
import torch
import torch.nn.functional as F

CROP = 64
EXPANSION = 1.5


def _cameras(frame: SynthFrame, flipped: bool):
    """Crop cameras (float64) of the frame's hands, all flipped or none."""
    boxes = torch.as_tensor(np.stack([hand.box_xyxy for hand in frame.hands]))
    k = torch.as_tensor(frame.intrinsics.matrix()).expand(len(boxes), 3, 3)
    return build_crop_cameras(boxes, k, torch.full((len(boxes),), flipped), CROP, EXPANSION)


def _canonical_projection(frame: SynthFrame, cameras) -> torch.Tensor:
    """Joints (N, 21, 2) projected through the crop cameras into canonical crop pixels."""
    joints = torch.as_tensor(np.stack([hand.joints_cam for hand in frame.hands]))
    points_h = joints @ cameras.rotation_h_from_c.transpose(-1, -2)
    pixels = geometry.project_points(points_h.numpy(), cameras.intrinsics.numpy()[:, None])
    normalized = pixels_to_normalized(torch.as_tensor(pixels), CROP, CROP)
    return normalized_to_pixels(flip_normalized(normalized, cameras.flipped), CROP, CROP)


@pytest.mark.parametrize('flipped', [False, True])
def test_crop_projection_maps_to_image_projection(synth_frame: SynthFrame,
                                                  flipped: bool) -> None:
    cameras = _cameras(synth_frame, flipped)
    crop_px = _canonical_projection(synth_frame, cameras)
    image_px = np.stack([hand.joints_2d for hand in synth_frame.hands])
    mapped = apply_homography(cameras.crop_to_image_homography(), crop_px)
    np.testing.assert_allclose(mapped.numpy(), image_px, atol=1e-8)


@pytest.mark.parametrize('flipped', [False, True])
def test_warped_image_shows_the_projected_joints(synth_frame: SynthFrame, flipped: bool) -> None:
    """Warp an image whose pixels hold their own coordinates; read it at the crop projections."""
    width, height = synth_frame.intrinsics.width, synth_frame.intrinsics.height
    v, u = torch.meshgrid(torch.arange(height, dtype=torch.float64),
                          torch.arange(width, dtype=torch.float64), indexing='ij')
    coordinate_image = torch.stack([u, v])[None]
    cameras = _cameras(synth_frame, flipped)
    crops = warp_to_crop(coordinate_image, torch.zeros(2, dtype=torch.long), cameras)
    crop_px = _canonical_projection(synth_frame, cameras)
    grid = pixels_to_normalized(crop_px, CROP, CROP)[:, None]
    read = F.grid_sample(crops, grid, align_corners=False)[:, :, 0].transpose(1, 2)
    image_px = np.stack([hand.joints_2d for hand in synth_frame.hands])
    # Joints outside the crop or the image (fingers past the image border) read padding, and so
    # do those within one crop pixel's footprint of the border (bilinear reads reach past it).
    boxes = np.stack([hand.box_xyxy for hand in synth_frame.hands])
    margin = (EXPANSION * (boxes[:, 2:] - boxes[:, :2]).max(axis=1) / CROP + 1.0)[:, None]
    inside = ((grid[:, 0].abs() < 0.98).all(dim=-1).numpy()
              & (image_px >= margin[..., None]).all(axis=-1)
              & (image_px[..., 0] < width - 1 - margin) & (image_px[..., 1] < height - 1 - margin))
    assert inside.sum() >= 30
    np.testing.assert_allclose(read.numpy()[inside], image_px[inside], atol=0.02)


def test_box_centre_is_the_crop_centre_and_the_box_fits(synth_frame: SynthFrame) -> None:
    cameras = _cameras(synth_frame, False)
    homography = cameras.crop_to_image_homography()
    centre = torch.full((2, 1, 2), (CROP - 1) / 2.0, dtype=torch.float64)
    boxes = np.stack([hand.box_xyxy for hand in synth_frame.hands])
    np.testing.assert_allclose(apply_homography(homography, centre)[:, 0].numpy(),
                               (boxes[:, :2] + boxes[:, 2:]) / 2.0 - 0.5, atol=1e-9)
    half = EXPANSION * (boxes[:, 2:] - boxes[:, :2]).max(axis=1) / 2.0
    box_centre = (boxes[:, :2] + boxes[:, 2:]) / 2.0 - 0.5
    corners = box_centre[:, None] + np.array([[-1, -1], [1, -1], [-1, 1], [1, 1]]) * half[
        :, None, None]
    in_crop = apply_homography(torch.linalg.inv(homography), torch.as_tensor(corners))
    assert (in_crop >= -0.5 - 1e-9).all() and (in_crop <= CROP - 0.5 + 1e-9).all()
    # The fit is tight: one corner coordinate touches the crop edge.
    edge = torch.minimum(in_crop + 0.5, CROP - 0.5 - in_crop).flatten(1).amin(dim=1)
    np.testing.assert_allclose(edge.numpy(), 0.0, atol=1e-9)


def test_centred_box_gives_identity_rotation() -> None:
    k = torch.tensor([[[200.0, 0, 50.0], [0, 200.0, 40.0], [0, 0, 1]]], dtype=torch.float64)
    box = torch.tensor([[40.5, 30.5, 60.5, 50.5]], dtype=torch.float64)
    cameras = build_crop_cameras(box, k, torch.tensor([False]), CROP, 2.0)
    np.testing.assert_allclose(cameras.rotation_h_from_c[0].numpy(), np.eye(3), atol=1e-12)
    np.testing.assert_allclose(cameras.intrinsics[0, 0, 0].item(), 200.0 * CROP / 40.0)


def test_flipped_crop_of_mirrored_image_is_the_crop(rng: np.random.Generator,
                                                    synth_frame: SynthFrame) -> None:
    width = synth_frame.intrinsics.width
    image = torch.as_tensor(rng.uniform(size=(1, 3, 168, width)))
    k = torch.as_tensor(synth_frame.intrinsics.matrix())[None]
    boxes = torch.as_tensor(np.stack([hand.box_xyxy for hand in synth_frame.hands]))
    # Mirroring the image maps pixel u to W - 1 - u: cx -> W - 1 - cx, box [x0, x1) -> [W - x1,
    # W - x0).
    k_mirror = k.clone()
    k_mirror[:, 0, 2] = width - 1 - k[:, 0, 2]
    boxes_mirror = boxes.clone()
    boxes_mirror[:, 0], boxes_mirror[:, 2] = width - boxes[:, 2], width - boxes[:, 0]
    index = torch.zeros(2, dtype=torch.long)
    crops = warp_to_crop(image, index, build_crop_cameras(
        boxes, k.expand(2, 3, 3), torch.tensor([False, False]), CROP, EXPANSION))
    crops_mirror = warp_to_crop(image.flip(-1), index, build_crop_cameras(
        boxes_mirror, k_mirror.expand(2, 3, 3), torch.tensor([True, True]), CROP, EXPANSION))
    np.testing.assert_allclose(crops_mirror.numpy(), crops.numpy(), atol=1e-10)


def test_flip_normalized_is_an_involution(rng: np.random.Generator) -> None:
    points = torch.as_tensor(rng.uniform(-1, 1, (3, 21, 2)))
    flipped = torch.tensor([True, False, True])
    once = flip_normalized(points, flipped)
    np.testing.assert_array_equal(once[1].numpy(), points[1].numpy())
    np.testing.assert_array_equal(once[0, :, 0].numpy(), -points[0, :, 0].numpy())
    np.testing.assert_array_equal(flip_normalized(once, flipped).numpy(), points.numpy())


def test_empty_box_is_rejected() -> None:
    k = torch.eye(3)[None]
    with pytest.raises(InputError, match='no area'):
        build_crop_cameras(torch.tensor([[5.0, 5.0, 5.0, 5.0]]), k, torch.tensor([False]), 8, 1.5)
