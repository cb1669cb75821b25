"""Ground-truth consistency of synthetic sequences (the generator's contract)."""

from dataclasses import replace

from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.synth.render import HandGeometry
from infinihand_ros.synth.render import render_frame
from infinihand_ros.synth.render import RenderOptions
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
import torch

SMALL = SynthConfig(width=160, height=120, noise_sigma=2.0)


@pytest.fixture(scope='module')
def frames() -> list:
    """Twelve frames of a small sequence, rendered once for the module."""
    sequence = SyntheticSequence(SMALL, seed=5, num_frames=40)
    return [sequence.frame(i) for i in range(0, 40, 3)]


def test_projection_of_camera_joints_gives_the_2d_joints(frames: list) -> None:
    for frame in frames:
        for hand in frame.hands:
            expected = geometry.project_points(hand.joints_cam, frame.intrinsics.matrix())
            np.testing.assert_allclose(hand.joints_2d, expected, atol=1e-9)


def test_world_joints_are_the_pose_applied_to_camera_joints(frames: list) -> None:
    for frame in frames:
        for hand in frame.hands:
            np.testing.assert_allclose(frame.camera_pose.to_world(hand.joints_cam),
                                       hand.joints_world, atol=1e-9)


def test_first_camera_is_the_world_frame() -> None:
    sequence = SyntheticSequence(SMALL, seed=5, num_frames=3)
    np.testing.assert_allclose(sequence.camera_pose(0).matrix(), np.eye(4), atol=1e-12)


def test_masks_agree_with_boxes_and_visibility(frames: list) -> None:
    seen_visible = False
    for frame in frames:
        masks = [hand.mask for hand in frame.hands]
        assert not np.any(masks[0] & masks[-1]) or len(masks) == 1
        for hand in frame.hands:
            count = int(hand.mask.sum())
            assert hand.visible == (count >= SMALL.min_visible_px)
            if not hand.visible:
                np.testing.assert_array_equal(hand.box_xyxy, 0)
                continue
            seen_visible = True
            x0, y0, x1, y1 = hand.box_xyxy.astype(int)
            inside = np.zeros_like(hand.mask)
            inside[y0:y1, x0:x1] = True
            assert not np.any(hand.mask & ~inside)
            # Tight: every edge row/column of the box holds mask pixels.
            assert hand.mask[y0].any() and hand.mask[y1 - 1].any()
            assert hand.mask[:, x0].any() and hand.mask[:, x1 - 1].any()
            assert np.all(np.isfinite(frame.depth[hand.mask]))
    assert seen_visible, 'the sequence never shows a hand; the test would check nothing'


def test_depth_at_joint_pixels_is_never_behind_the_joint(frames: list) -> None:
    checked = 0
    for frame in frames:
        for hand in frame.hands:
            pixels = np.round(hand.joints_2d).astype(int)
            for joint, (u, v) in enumerate(pixels):
                z = hand.joints_cam[joint, 2]
                if 0 <= u < SMALL.width and 0 <= v < SMALL.height and z > 0 and hand.mask[v, u]:
                    checked += 1
                    # The joint is inside its limb, so the first surface on its ray is at most
                    # at the joint's depth (pixel rounding adds well under 2 mm here).
                    assert frame.depth[v, u] <= z + 2e-3
    assert checked >= 20


def test_depth_at_unoccluded_joints_is_within_the_limb_radius() -> None:
    """A flat open hand facing the camera: no joint hides another, so each is seen directly."""
    sequence = SyntheticSequence(SMALL, seed=5, num_frames=1)
    track = sequence.tracks[-1]
    model = BuiltinHandModel(track.side).double()
    # Palm towards the camera: rotate the canonical hand (palm -y) so the palm faces -z.
    orient = torch.tensor([[np.pi / 2, 0.0, 0.0]], dtype=torch.float64)
    with torch.no_grad():
        joints = model(orient, torch.zeros(1, 15, 3, dtype=torch.float64),
                       torch.zeros(1, 10, dtype=torch.float64),
                       torch.tensor([[0.09, 0.0, 0.45]], dtype=torch.float64)).joints[0].numpy()
    k = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    # Camera at the origin looking along +z (scene pose = identity), hand 0.45 m in front.
    out = render_frame(sequence.scene, k, np.eye(4), 640, 480,
                       [HandGeometry(track.side, joints, track.radii, track.skin_rgb)],
                       RenderOptions(noise_sigma=0.0))
    pixels = np.round(geometry.project_points(joints, k)).astype(int)
    depth = out.depth[pixels[:, 1], pixels[:, 0]]
    assert out.hand_masks[track.side][pixels[:, 1], pixels[:, 0]].all()
    assert np.all(depth <= joints[:, 2] + 1e-3)
    assert np.all(depth >= joints[:, 2] - track.radii.max() - 1e-3)


def test_same_seed_same_frames_other_seed_differs() -> None:
    a = SyntheticSequence(SMALL, seed=11, num_frames=5).frame(4)
    b = SyntheticSequence(SMALL, seed=11, num_frames=5).frame(4)
    c = SyntheticSequence(SMALL, seed=12, num_frames=5).frame(4)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.hands[0].joints_world, b.hands[0].joints_world)
    assert not np.array_equal(a.rgb, c.rgb)


def test_one_hand_sequences_and_bad_settings() -> None:
    left_only = SyntheticSequence(SynthConfig(width=64, height=48, hands='left'), 1, 2).frame(1)
    assert [hand.side for hand in left_only.hands] == [0]
    with pytest.raises(InputError, match="hands must be one of .* got 'three'"):
        SynthConfig(hands='three')
    with pytest.raises(InputError, match='fps'):
        SynthConfig(fps=0.0)
    with pytest.raises(InputError, match='jpeg_quality must be 0'):
        SynthConfig(jpeg_quality=-1)
    with pytest.raises(InputError, match='frames must be >= 1'):
        SyntheticSequence(SMALL, 1, 0)


def test_exposure_blurs_the_image_only_and_is_bounded_by_the_frame_interval() -> None:
    still = SyntheticSequence(replace(SMALL, exposure_s=0.0), seed=7, num_frames=12)
    exposed = SyntheticSequence(replace(SMALL, exposure_s=0.02), seed=7, num_frames=12)
    changed = 0
    for index in (0, 6, 11):  # the ends extrapolate the motion
        a, b = still.frame(index), exposed.frame(index)
        np.testing.assert_array_equal(a.depth, b.depth)
        for hand_a, hand_b in zip(a.hands, b.hands):
            np.testing.assert_array_equal(hand_a.mask, hand_b.mask)
            np.testing.assert_array_equal(hand_a.joints_world, hand_b.joints_world)
        changed += int(np.abs(a.rgb.astype(int) - b.rgb.astype(int)).mean() > 0.5)
    assert changed >= 2
    with pytest.raises(InputError, match=r'exposure_s must be within \[0, 1 / fps = 0.1\] s'):
        SynthConfig(exposure_s=0.2)
