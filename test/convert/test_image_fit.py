"""Tests of fitting frames to the dataset's video size (infinihand_ros/convert/image_fit.py)."""

from infinihand_ros.convert.image_fit import CROP
from infinihand_ros.convert.image_fit import fit_frame
from infinihand_ros.convert.image_fit import FrameFitter
from infinihand_ros.convert.image_fit import LETTERBOX
from infinihand_ros.convert.image_fit import parse_video_size
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import ConfigError
import numpy as np
import pytest

SOURCE = (640, 480)
TARGET = (518, 378)
BLOB = (401.3, 207.8)  # source pixel centre of the test blob (inside the crop's window)


def _blob_image(size: tuple[int, int], centre: tuple[float, float],
                sigma: float = 7.0) -> np.ndarray:
    """Return a (H, W, 3) uint8 image holding one Gaussian blob at ``centre`` (pixels)."""
    ys, xs = np.mgrid[0:size[1], 0:size[0]]
    blob = np.exp(-((xs - centre[0]) ** 2 + (ys - centre[1]) ** 2) / (2 * sigma ** 2))
    return np.repeat((blob * 255).round().astype(np.uint8)[..., None], 3, axis=2)


def _centroid(rgb: np.ndarray) -> np.ndarray:
    weights = rgb[..., 0].astype(np.float64)
    ys, xs = np.mgrid[0:rgb.shape[0], 0:rgb.shape[1]]
    return np.array([(xs * weights).sum(), (ys * weights).sum()]) / weights.sum()


def _project(intrinsics: Intrinsics, points_cam: np.ndarray) -> np.ndarray:
    uv = points_cam @ intrinsics.matrix().T
    return uv[:, :2] / uv[:, 2:]


@pytest.mark.parametrize('mode', [LETTERBOX, CROP])
def test_pixels_move_where_the_mapping_says(mode: str) -> None:
    frame = SourceFrame(0, _blob_image(SOURCE, BLOB), None)
    fitted, mapping = fit_frame(frame, TARGET, mode)
    assert fitted.rgb.shape == (TARGET[1], TARGET[0], 3)
    expected = mapping.points_to_model(np.array([BLOB]))[0]
    np.testing.assert_allclose(_centroid(fitted.rgb), expected, atol=0.05)


@pytest.mark.parametrize('mode', [LETTERBOX, CROP])
def test_mapped_intrinsics_project_where_the_pixels_went(mode: str) -> None:
    intrinsics = Intrinsics(520.0, 515.0, 322.4, 236.1, *SOURCE)
    frame = SourceFrame(0, np.zeros((SOURCE[1], SOURCE[0], 3), np.uint8), intrinsics)
    fitted, mapping = fit_frame(frame, TARGET, mode)
    assert (fitted.intrinsics.width, fitted.intrinsics.height) == TARGET
    points = np.random.default_rng(0).uniform([-0.3, -0.2, 0.5], [0.3, 0.2, 2.0], (50, 3))
    np.testing.assert_allclose(_project(fitted.intrinsics, points),
                               mapping.points_to_model(_project(intrinsics, points)), atol=1e-9)


def test_letterbox_keeps_everything_and_crop_fills_the_frame() -> None:
    frame = SourceFrame(0, np.full((SOURCE[1], SOURCE[0], 3), 200, np.uint8), None)
    boxed, box_map = fit_frame(frame, TARGET, LETTERBOX)
    cropped, crop_map = fit_frame(frame, TARGET, CROP)
    # 640x480 -> scale 378/480: 504x378 centred, 7 black columns each side.
    assert box_map.content_box == (7, 0, 511, 378)
    assert boxed.rgb[:, :7].max() == 0 and boxed.rgb[:, 7:511].min() == 200
    assert cropped.rgb.min() == 200
    assert crop_map.scale_x == pytest.approx(518 / 640) and box_map.scale_x < crop_map.scale_x


def test_fitter_records_identity_for_frames_of_the_dataset_size() -> None:
    fitter = FrameFitter((160, 120), LETTERBOX)
    frame = SourceFrame(0, np.zeros((119, 159, 3), np.uint8), None)
    assert fitter.fit(frame) is frame  # odd sizes are padded by the video writer, not scaled
    assert fitter.record['mode'] == 'none' and fitter.record['source_size'] == [159, 119]
    other = FrameFitter((160, 120), CROP)
    fitted = other.fit(SourceFrame(0, np.zeros((90, 200, 3), np.uint8), None))
    assert fitted.rgb.shape == (120, 160, 3)
    assert other.record['mode'] == CROP and other.record['source_size'] == [200, 90]
    assert other.record['video_size'] == [160, 120]


def test_video_size_text() -> None:
    assert parse_video_size('640x480') == (640, 480)
    assert parse_video_size('') is None
    for bad in ('640', '640x', 'axb', '0x10', '640x480x3'):
        with pytest.raises(ConfigError, match='expected WIDTHxHEIGHT'):
            parse_video_size(bad)
