"""Lens distortion as data (the CameraInfo models) and its maths through OpenCV.

A lens is pinhole (model None, no coefficients) or one of the ``sensor_msgs/CameraInfo``
models, with its coefficients in the order ROS and OpenCV use:

- ``plumb_bob``: k1, k2, p1, p2, k3 (Brown-Conrady, OpenCV's 5-coefficient model);
- ``rational_polynomial``: k1, k2, p1, p2, k3, k4, k5, k6 (OpenCV's 8-coefficient model);
- ``equidistant``: k1, k2, k3, k4 (the fisheye model of ``cv2.fisheye``: the radius grows
  with the ray's angle, r = f * theta * (1 + k1 theta^2 + ...), so even zeros bend rays).

The coefficients act on normalised camera coordinates, so they hold for any image that is a
scale and shift of the calibrated one (resized, cropped, letterboxed): only K changes.
Pixels are OpenCV's (pixel centres at integers). Point maths goes through ``cv2`` and
``cv2.fisheye`` (``projectPoints``, ``undistortPoints``).
"""

import math
import numbers
from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
import numpy as np

PLUMB_BOB: Final = 'plumb_bob'
RATIONAL_POLYNOMIAL: Final = 'rational_polynomial'
EQUIDISTANT: Final = 'equidistant'
#: The coefficient names of each model, in order.
COEFFICIENT_NAMES: Final = {
    PLUMB_BOB: ('k1', 'k2', 'p1', 'p2', 'k3'),
    RATIONAL_POLYNOMIAL: ('k1', 'k2', 'p1', 'p2', 'k3', 'k4', 'k5', 'k6'),
    EQUIDISTANT: ('k1', 'k2', 'k3', 'k4'),
}
DISTORTION_MODELS: Final = tuple(COEFFICIENT_NAMES)
#: Separates the model from its coefficients in ``parse_distortion``'s text.
MODEL_SEPARATOR: Final = ':'
#: Iterations and tolerance of OpenCV's iterative undistortion of points.
_UNDISTORT_CRITERIA: Final = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)


def check_distortion(model: object, coefficients: object, name: str = 'intrinsics'
                     ) -> tuple[str | None, tuple[float, ...]]:
    """Return a lens's (model, coefficients) checked; (None, ()) is pinhole.

    ``plumb_bob`` or ``rational_polynomial`` with all coefficients zero is the pinhole camera:
    (None, ()) too. ``equidistant`` with zeros is not (r = f * theta, not f * tan(theta)).

    Args:
        model: a name of ``DISTORTION_MODELS``, or None (or '') for pinhole.
        coefficients: the model's coefficients (any sequence of real numbers), in order.
        name: what the caller calls the lens, for the error messages.

    Raises:
        InputError: for an unknown model, coefficients without a model, a wrong count, or a
            value that is not a finite number.

    """
    if isinstance(coefficients, (str, bytes)) or not isinstance(
            coefficients, (list, tuple, np.ndarray, type(None))):
        raise InputError(f'{name}: distortion coefficients must be a list of numbers, got '
                         f'{coefficients!r}')
    values = [] if coefficients is None else list(np.asarray(coefficients, dtype=object).ravel())
    if model is None or model == '':
        if values:
            raise InputError(f'{name}: distortion coefficients {values} without a distortion '
                             f'model; name one of {list(DISTORTION_MODELS)}')
        return None, ()
    if model not in COEFFICIENT_NAMES:
        raise InputError(f'{name}: distortion model {model!r} is not supported; use one of '
                         f'{list(DISTORTION_MODELS)} (or none for a pinhole camera)')
    names = COEFFICIENT_NAMES[model]
    if len(values) != len(names):
        raise InputError(f'{name}: the {model} model takes {len(names)} coefficients '
                         f'({", ".join(names)}), got {len(values)}')
    checked = []
    for coefficient, value in zip(names, values):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) or (
                not math.isfinite(float(value))):
            raise InputError(f'{name}: {model} coefficient {coefficient} must be a finite '
                             f'number, got {value!r}')
        checked.append(float(value))
    if model != EQUIDISTANT and not any(checked):
        return None, ()  # zero polynomial coefficients bend no ray: the pinhole camera
    return str(model), tuple(checked)


def parse_distortion(text: str, name: str = '--distortion'
                     ) -> tuple[str, tuple[float, ...]]:
    """Return (model, coefficients) of ``'MODEL:c1,c2,...'`` (e.g. ``plumb_bob:-0.25,0.08,0,0,0``).

    Raises:
        InputError: naming ``name`` for a missing separator, an unknown model, a wrong count or
            a coefficient that is not a finite number.

    """
    model, separator, values = text.partition(MODEL_SEPARATOR)
    model = model.strip()
    if not separator or not values.strip():
        raise InputError(f'{name} {text!r}: expected MODEL{MODEL_SEPARATOR}c1,c2,... with MODEL '
                         f'one of {list(DISTORTION_MODELS)} (e.g. '
                         f'plumb_bob{MODEL_SEPARATOR}-0.25,0.08,0,0,0)')
    try:
        coefficients = [float(part) for part in values.split(',')]
    except ValueError as exc:
        raise InputError(f'{name} {text!r}: coefficients must be numbers ({exc})') from exc
    checked_model, checked = check_distortion(model, coefficients, name)
    return checked_model, checked


def _coefficients(model: str, coefficients: tuple[float, ...]) -> np.ndarray:
    """Return the float64 coefficient vector OpenCV takes for ``model``."""
    return np.asarray(coefficients, dtype=np.float64).reshape(-1, 1 if model == EQUIDISTANT
                                                              else len(coefficients))


def project_points(points_cam: np.ndarray, K: np.ndarray, model: str | None,
                   coefficients: tuple[float, ...]) -> np.ndarray:
    """Project camera-frame points (N, 3), metres, to distorted pixels (N, 2), float64.

    Pinhole (``model`` None) divides by depth; points must lie in front of the camera.
    """
    points = np.asarray(points_cam, dtype=np.float64).reshape(-1, 1, 3)
    zero = np.zeros(3)
    if model is None:
        pixels, _ = cv2.projectPoints(points, zero, zero, K, None)
    elif model == EQUIDISTANT:
        pixels, _ = cv2.fisheye.projectPoints(points, zero, zero, K,
                                              _coefficients(model, coefficients))
    else:
        pixels, _ = cv2.projectPoints(points, zero, zero, K, _coefficients(model, coefficients))
    return pixels.reshape(-1, 2)


def distort_pixels(pinhole_px: np.ndarray, K: np.ndarray, model: str | None,
                   coefficients: tuple[float, ...]) -> np.ndarray:
    """Map pixels (N, 2) of the pinhole camera with K to the distorted camera's pixels (N, 2)."""
    pixels = np.asarray(pinhole_px, dtype=np.float64).reshape(-1, 2)
    homogeneous = np.column_stack([pixels, np.ones(len(pixels))])
    rays = homogeneous @ np.linalg.inv(K).T
    return project_points(rays, K, model, coefficients)


def undistort_pixels(distorted_px: np.ndarray, K: np.ndarray, model: str | None,
                     coefficients: tuple[float, ...]) -> np.ndarray:
    """Map distorted pixels (N, 2) to the pixels (N, 2) of the pinhole camera with the same K."""
    pixels = np.asarray(distorted_px, dtype=np.float64).reshape(-1, 1, 2)
    if model is None:
        return pixels.reshape(-1, 2).copy()
    if model == EQUIDISTANT:
        out = cv2.fisheye.undistortPoints(pixels, K, _coefficients(model, coefficients), P=K,
                                          criteria=_UNDISTORT_CRITERIA)
    else:
        out = cv2.undistortPoints(pixels, K, _coefficients(model, coefficients), R=None, P=K,
                                  criteria=_UNDISTORT_CRITERIA)
    return out.reshape(-1, 2)


def rectification_maps(K: np.ndarray, model: str, coefficients: tuple[float, ...],
                       size: tuple[int, int], target_K: np.ndarray | None = None,
                       target_size: tuple[int, int] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Return ``cv2.remap`` maps that render the distorted image as a pinhole one.

    Args:
        K: (3, 3) intrinsics of the distorted image.
        model: a distortion model (not None).
        coefficients: its coefficients.
        size: (width, height) of the distorted image (only to default ``target_size``).
        target_K: (3, 3) K of the pinhole image; default ``K``.
        target_size: (width, height) of the pinhole image; default ``size``.

    Returns:
        (map1, map2) in OpenCV's fixed-point form (CV_16SC2 and CV_16UC1): for every pinhole
        pixel, where to read the distorted image.

    """
    target_K = K if target_K is None else target_K
    target_size = size if target_size is None else target_size
    if model == EQUIDISTANT:
        return cv2.fisheye.initUndistortRectifyMap(
            K, _coefficients(model, coefficients), np.eye(3), target_K, target_size,
            cv2.CV_16SC2)
    return cv2.initUndistortRectifyMap(K, _coefficients(model, coefficients), None, target_K,
                                       target_size, cv2.CV_16SC2)
