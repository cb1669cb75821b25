"""sensor_msgs Image, CompressedImage and CameraInfo <-> numpy images and ``Intrinsics``.

Compressed images follow image_transport's ``compressed`` plugin: ``format`` reads
``'<original encoding>; <jpeg|png> compressed <bgr8|rgb8>'``.

CameraInfo's ``distortion_model`` and ``d`` are read into the intrinsics' lens
(``core.distortion``: ``plumb_bob``, ``rational_polynomial``, ``equidistant``); an empty ``d``
(an uncalibrated driver) is a pinhole camera. A pinhole camera is written as ``plumb_bob`` with
five zeros, as camera drivers do.

Builders take a rosbags typestore; the readers only use message attributes, so they accept rosbags
messages and rclpy messages alike.
"""

from typing import Any, Final

import cv2
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import CAMERA_INFO_MSG
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.distortion import COEFFICIENT_NAMES
from infinihand_ros.core.distortion import DISTORTION_MODELS
from infinihand_ros.core.errors import InputError
import numpy as np
from rosbags.typesys.store import Typestore

#: Channels of each supported encoding; images inside the core are always RGB uint8.
ENCODING_CHANNELS: Final = {'rgb8': 3, 'bgr8': 3, 'mono8': 1}
#: What a pinhole camera is written as: plumb_bob with five zero coefficients.
DISTORTION_MODEL: Final = 'plumb_bob'
#: Codecs of CompressedImage messages, with their OpenCV file extensions.
CODEC_EXTENSIONS: Final = {'jpeg': '.jpg', 'png': '.png'}


def image_to_msg(typestore: Typestore, rgb: np.ndarray, timestamp_ns: int, frame_id: str) -> Any:
    """Build an rgb8 ``sensor_msgs/msg/Image`` from an (H, W, 3) uint8 array."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise InputError(f'image: expected (H, W, 3) uint8 RGB, got {rgb.shape} {rgb.dtype}')
    height, width = rgb.shape[:2]
    header = typestore.types[HEADER_MSG](stamp=stamp_from_ns(typestore, timestamp_ns),
                                         frame_id=frame_id)
    return typestore.types[IMAGE_MSG](
        header=header, height=height, width=width, encoding='rgb8', is_bigendian=0,
        step=width * 3, data=np.ascontiguousarray(rgb).reshape(-1))


def msg_to_image(msg: Any) -> np.ndarray:
    """Return an Image message's pixels as (H, W, 3) uint8 RGB.

    Raises:
        InputError: for an unsupported encoding, an empty image or a size/step mismatch.

    """
    encoding = str(msg.encoding)
    if encoding not in ENCODING_CHANNELS:
        raise InputError(f'image encoding {encoding!r} is not supported; publish one of '
                         f'{sorted(ENCODING_CHANNELS)}')
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    channels = ENCODING_CHANNELS[encoding]
    if height == 0 or width == 0:
        raise InputError(f'image is empty ({width}x{height})')
    data = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if step < width * channels or data.size < step * height:
        raise InputError(f'image {width}x{height} {encoding}: step {step} and {data.size} bytes '
                         f'do not hold the pixels')
    pixels = data[:step * height].reshape(height, step)[:, :width * channels]
    pixels = pixels.reshape(height, width, channels)
    if encoding == 'bgr8':
        return cv2.cvtColor(pixels, cv2.COLOR_BGR2RGB)  # contiguous; 40x faster than a flip
    if encoding == 'mono8':
        return np.repeat(pixels, 3, axis=2)
    return pixels


def image_to_compressed_msg(typestore: Typestore, rgb: np.ndarray, timestamp_ns: int,
                            frame_id: str, codec: str, jpeg_quality: int = 90) -> Any:
    """Build a ``sensor_msgs/msg/CompressedImage`` (jpeg or png of bgr8, as image_transport)."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise InputError(f'image: expected (H, W, 3) uint8 RGB, got {rgb.shape} {rgb.dtype}')
    if codec not in CODEC_EXTENSIONS:
        raise InputError(f'image codec must be one of {sorted(CODEC_EXTENSIONS)}, got {codec!r}')
    params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)] if codec == 'jpeg' else []
    ok, encoded = cv2.imencode(CODEC_EXTENSIONS[codec], rgb[:, :, ::-1], params)
    if not ok:
        raise InputError(f'image: OpenCV could not encode a {rgb.shape} image as {codec}')
    header = typestore.types[HEADER_MSG](stamp=stamp_from_ns(typestore, timestamp_ns),
                                         frame_id=frame_id)
    return typestore.types[COMPRESSED_IMAGE_MSG](
        header=header, format=f'rgb8; {codec} compressed bgr8', data=encoded.reshape(-1))


def compressed_msg_to_image(msg: Any) -> np.ndarray:
    """Decode a CompressedImage message (jpeg or png) into (H, W, 3) uint8 RGB.

    Raises:
        InputError: for empty or undecodable data.

    """
    data = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    fmt = str(msg.format)
    if data.size == 0:
        raise InputError(f'compressed image ({fmt!r}) is empty')
    decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
    if decoded is None:
        raise InputError(f'compressed image ({fmt!r}, {data.size} bytes) could not be decoded; '
                         "publish jpeg or png through image_transport's compressed plugin")
    # OpenCV decodes to BGR; a stream stored as rgb8 was encoded with swapped channels.
    if fmt.endswith('compressed rgb8'):
        return decoded
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)


def camera_info_to_msg(typestore: Typestore, intrinsics: Intrinsics, timestamp_ns: int,
                       frame_id: str) -> Any:
    """Build a ``sensor_msgs/msg/CameraInfo`` of the intrinsics and their lens distortion."""
    model, d = camera_info_distortion(intrinsics)
    k = intrinsics.matrix()
    projection = np.hstack([k, np.zeros((3, 1))])
    header = typestore.types[HEADER_MSG](stamp=stamp_from_ns(typestore, timestamp_ns),
                                         frame_id=frame_id)
    roi = typestore.types['sensor_msgs/msg/RegionOfInterest'](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return typestore.types[CAMERA_INFO_MSG](
        header=header, height=intrinsics.height, width=intrinsics.width,
        distortion_model=model, d=np.asarray(d, np.float64), k=k.reshape(-1),
        r=np.eye(3).reshape(-1),
        p=projection.reshape(-1), binning_x=0, binning_y=0, roi=roi)


def camera_info_distortion(intrinsics: Intrinsics) -> tuple[str, list[float]]:
    """Return CameraInfo's (``distortion_model``, ``d``) of the intrinsics' lens."""
    if intrinsics.distortion_model is None:
        return DISTORTION_MODEL, [0.0] * len(COEFFICIENT_NAMES[DISTORTION_MODEL])
    return intrinsics.distortion_model, list(intrinsics.distortion)


def camera_info_to_intrinsics(msg: Any) -> Intrinsics:
    """Read ``Intrinsics``, lens distortion included, from a CameraInfo message.

    Raises:
        InputError: when K is all zeros (uncalibrated), holds NaN, the size is zero, or the
            distortion model is unknown or has the wrong number of coefficients.

    """
    k = np.asarray(msg.k, dtype=np.float64).reshape(3, 3)
    if not np.any(k):
        raise InputError('camera_info: K is all zeros (camera not calibrated); calibrate it or '
                         'let the model predict the field of view')
    intrinsics = Intrinsics.from_matrix(k, int(msg.width), int(msg.height))
    model = str(getattr(msg, 'distortion_model', ''))
    d = [float(value) for value in np.asarray(getattr(msg, 'd', ()), dtype=np.float64).ravel()]
    if not d or (not model and not any(d)):
        return intrinsics  # an uncalibrated lens: pinhole
    if model not in DISTORTION_MODELS:
        raise InputError(f'camera_info: distortion model {model!r} is not supported (use one '
                         f'of {list(DISTORTION_MODELS)}); publish the rectified image '
                         '(image_proc) with its CameraInfo instead, or recalibrate with a '
                         'supported model')
    try:
        return Intrinsics(intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy,
                          intrinsics.width, intrinsics.height, model, d)
    except InputError as exc:
        raise InputError(f'camera_info: {exc}') from exc
