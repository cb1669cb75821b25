"""Lens distortion as data and its OpenCV maths (core/distortion.py, Intrinsics' lens)."""

import cv2
from infinihand_ros.core import distortion
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
import numpy as np
import pytest

K = np.array([[300.0, 0.0, 161.0], [0.0, 305.0, 118.0], [0.0, 0.0, 1.0]])
LENSES = {
    distortion.PLUMB_BOB: (-0.25, 0.08, 0.001, -0.002, 0.01),
    distortion.RATIONAL_POLYNOMIAL: (-0.2, 0.05, 0.001, 0.001, 0.01, 0.02, 0.01, 0.005),
    distortion.EQUIDISTANT: (0.05, -0.01, 0.003, -0.001),
}


def _points(count: int = 60) -> np.ndarray:
    """Camera-frame points (N, 3) inside a 320x240 view, 0.3..2 m away."""
    rng = np.random.default_rng(3)
    rays = np.column_stack([rng.uniform(-0.5, 0.5, (count, 1)),
                            rng.uniform(-0.38, 0.38, (count, 1)), np.ones(count)])
    return rays * rng.uniform(0.3, 2.0, (count, 1))


@pytest.mark.parametrize('model', sorted(LENSES))
def test_projection_matches_opencv(model: str) -> None:
    """project_points is cv2.projectPoints (cv2.fisheye for equidistant) with zero pose."""
    points, coefficients = _points(), LENSES[model]
    zero = np.zeros(3)
    if model == distortion.EQUIDISTANT:
        expected, _ = cv2.fisheye.projectPoints(points[:, None], zero, zero, K,
                                                np.array(coefficients))
    else:
        expected, _ = cv2.projectPoints(points, zero, zero, K, np.array(coefficients))
    got = distortion.project_points(points, K, model, coefficients)
    np.testing.assert_allclose(got, expected.reshape(-1, 2), atol=1e-9)


@pytest.mark.parametrize('model', sorted(LENSES))
def test_undistortion_round_trips(model: str) -> None:
    """Distorted projections undistort to the pinhole projection, and back."""
    points, coefficients = _points(), LENSES[model]
    pinhole = distortion.project_points(points, K, None, ())
    distorted = distortion.project_points(points, K, model, coefficients)
    assert np.abs(distorted - pinhole).max() > 1.0  # the lens does bend these rays
    np.testing.assert_allclose(distortion.undistort_pixels(distorted, K, model, coefficients),
                               pinhole, atol=1e-6)
    np.testing.assert_allclose(distortion.distort_pixels(pinhole, K, model, coefficients),
                               distorted, atol=1e-6)


@pytest.mark.parametrize('model', sorted(LENSES))
def test_rectification_maps_read_each_pinhole_pixel_where_the_lens_put_it(model: str) -> None:
    """Remapping the distorted image's own pixel coordinates gives distort_pixels everywhere."""
    coefficients = LENSES[model]
    ys, xs = np.mgrid[0:240, 0:320].astype(np.float32)
    map1, map2 = distortion.rectification_maps(K, model, coefficients, (320, 240))
    read_x = cv2.remap(xs, map1, map2, cv2.INTER_LINEAR, borderValue=-1)
    read_y = cv2.remap(ys, map1, map2, cv2.INTER_LINEAR, borderValue=-1)
    pinhole = np.column_stack([xs.ravel(), ys.ravel()])
    expected = distortion.distort_pixels(pinhole, K, model, coefficients).reshape(240, 320, 2)
    inside = ((expected[..., 0] >= 1) & (expected[..., 0] <= 318) & (expected[..., 1] >= 1)
              & (expected[..., 1] <= 238))
    assert inside.mean() > 0.9
    error = np.hypot(read_x - expected[..., 0], read_y - expected[..., 1])[inside]
    assert error.max() < 0.05  # OpenCV's fixed-point maps: 1/32 px steps


def test_intrinsics_carry_a_checked_lens() -> None:
    """Coefficients are coerced to floats; pinhole() and a mapped K keep or drop the lens."""
    lens = Intrinsics(300, 305, 161, 118, 320, 240, 'plumb_bob', np.array([-0.25, 0.08, 0, 0, 0]))
    assert lens.distortion == (-0.25, 0.08, 0.0, 0.0, 0.0)
    assert lens.is_distorted and not lens.pinhole().is_distorted
    assert lens.pinhole().distortion_model is None
    assert lens.with_matrix(600, 610, 322, 236, 640, 480).distortion == lens.distortion
    zeros = Intrinsics(300, 305, 161, 118, 320, 240, 'plumb_bob', (0,) * 5)
    assert zeros == zeros.pinhole() and zeros.distortion_model is None
    assert Intrinsics(300, 305, 161, 118, 320, 240, 'equidistant', (0,) * 4).is_distorted
    assert Intrinsics(300, 305, 161, 118, 320, 240).distortion_model is None


@pytest.mark.parametrize('model, coefficients, message', [
    ('fisheye', (0.1, 0, 0, 0), "distortion model 'fisheye' is not supported"),
    ('plumb_bob', (0.1, 0.2), 'plumb_bob model takes 5 coefficients'),
    ('equidistant', (0.1, 0.0, float('nan'), 0.0), 'coefficient k3 must be a finite number'),
    ('plumb_bob', ('a', 0, 0, 0, 0), 'coefficient k1 must be a finite number'),
    (None, (0.1,), 'without a distortion model'),
])
def test_bad_lenses_are_refused(model: str | None, coefficients: tuple, message: str) -> None:
    """An unknown model, a wrong count or a non-finite value raise, naming it."""
    with pytest.raises(InputError, match=message):
        Intrinsics(300, 305, 161, 118, 320, 240, model, coefficients)


def test_parse_distortion() -> None:
    """MODEL:c1,c2,... parses; errors name the option and the expected form."""
    assert distortion.parse_distortion('equidistant:0.1,0,0,0.01') == (
        'equidistant', (0.1, 0.0, 0.0, 0.01))
    with pytest.raises(InputError, match=r'--distortion .*expected MODEL:c1,c2'):
        distortion.parse_distortion('-0.25,0.08,0,0,0')
    with pytest.raises(InputError, match='coefficients must be numbers'):
        distortion.parse_distortion('plumb_bob:-0.25,x,0,0,0')
    with pytest.raises(InputError, match='--distortion: the rational_polynomial model takes 8'):
        distortion.parse_distortion('rational_polynomial:0.1,0,0,0,0')
