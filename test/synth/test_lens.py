"""Rendering through a distorting lens (synth/lens.py, ``SynthConfig.distortion``)."""

from dataclasses import replace

import cv2
from infinihand_ros.core import distortion
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.lens import lens_warp
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

SMALL = SynthConfig(width=160, height=120, noise_sigma=0.0, jpeg_quality=0, exposure_s=0.0)
LENSES = ('plumb_bob:-0.25,0.08,0,0,0', 'equidistant:0.08,-0.02,0.01,-0.005')


@pytest.mark.parametrize('lens', LENSES)
def test_the_warp_moves_pinhole_pixels_to_where_the_lens_puts_them(lens: str) -> None:
    """A point drawn on the pinhole canvas lands at its distorted projection."""
    model, coefficients = distortion.parse_distortion(lens)
    intrinsics = Intrinsics(120, 122, 81, 59, 160, 120, model, coefficients)
    warp = lens_warp(intrinsics)
    assert warp.canvas_size[0] >= 160 and warp.canvas_size[1] >= 120
    points = np.array([[0.5, 0.35, 1.0], [-0.55, -0.4, 1.0], [0.1, -0.2, 1.0]])
    canvas_x, canvas_y = np.meshgrid(np.arange(warp.canvas_size[0], dtype=np.float32),
                                     np.arange(warp.canvas_size[1], dtype=np.float32))
    read_x = cv2.remap(canvas_x, warp.map_x, warp.map_y, cv2.INTER_LINEAR, borderValue=-1)
    read_y = cv2.remap(canvas_y, warp.map_x, warp.map_y, cv2.INTER_LINEAR, borderValue=-1)
    distorted = distortion.project_points(points, intrinsics.matrix(), model, coefficients)
    on_canvas = geometry.project_points(points, warp.canvas_K)
    for (u, v), expected in zip(distorted, on_canvas):
        iu, iv = int(round(u)), int(round(v))
        # The map is smooth: the pixel nearest the distorted projection reads the canvas within
        # about a pixel of the point's pinhole position (the rounding, times the lens's scale).
        assert np.hypot(read_x[iv, iu] - expected[0], read_y[iv, iu] - expected[1]) < 1.5


@pytest.mark.parametrize('lens', LENSES)
def test_distorted_twin_shares_the_scene_and_projects_through_the_lens(lens: str) -> None:
    """Same seed: same K and motion; joints_2d are the lens's projections, on the hand masks."""
    pinhole = SyntheticSequence(SMALL, seed=5, num_frames=12)
    twin = SyntheticSequence(replace(SMALL, distortion=lens), seed=5, num_frames=12)
    np.testing.assert_array_equal(twin.intrinsics.matrix(), pinhole.intrinsics.matrix())
    assert twin.intrinsics.is_distorted
    assert twin.describe()['distortion_model'] == lens.split(':')[0]
    on_mask = total = 0
    for index in range(0, 12, 3):
        frame, plain = twin.frame(index), pinhole.frame(index)
        np.testing.assert_allclose(frame.camera_pose.matrix(), plain.camera_pose.matrix())
        for hand in frame.hands:
            np.testing.assert_allclose(
                hand.joints_2d, distortion.project_points(
                    hand.joints_cam, frame.intrinsics.matrix(),
                    frame.intrinsics.distortion_model, frame.intrinsics.distortion), atol=1e-9)
            pixels = np.round(hand.joints_2d).astype(int)
            inside = ((pixels[:, 0] >= 0) & (pixels[:, 0] < 160) & (pixels[:, 1] >= 0)
                      & (pixels[:, 1] < 120) & (hand.joints_cam[:, 2] > 0))
            if hand.visible:
                total += int(inside.sum())
                on_mask += int(hand.mask[pixels[inside, 1], pixels[inside, 0]].sum())
    assert total >= 20 and on_mask / total > 0.6


def test_bad_lens_setting_is_named() -> None:
    with pytest.raises(InputError, match='synth.distortion: the equidistant model takes 4'):
        SynthConfig(distortion='equidistant:0.1')
