"""Image / CompressedImage decoding of the estimator node (ros/estimator/image_decoding.py)."""

from dataclasses import dataclass
from types import SimpleNamespace

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.ros.estimator.image_decoding import compressed_codec
from infinihand_ros.ros.estimator.image_decoding import decode_image
import numpy as np
import pytest


@dataclass
class RawImage:
    """The fields of sensor_msgs/Image the decoder reads."""

    height: int
    width: int
    encoding: str
    step: int
    data: bytes


def compressed(fmt: str, data: bytes) -> SimpleNamespace:
    """Return the fields of sensor_msgs/CompressedImage the decoder reads."""
    return SimpleNamespace(format=fmt, data=data)


RGB = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)


def test_rgb8_bgr8_mono8_decode_to_rgb() -> None:
    """Each supported encoding gives the RGB pixels it encodes."""
    rgb = decode_image(RawImage(2, 3, 'rgb8', 9, RGB.tobytes()))
    np.testing.assert_array_equal(rgb, RGB)
    bgr = decode_image(RawImage(2, 3, 'bgr8', 9, RGB[:, :, ::-1].tobytes()))
    np.testing.assert_array_equal(bgr, RGB)
    mono = decode_image(RawImage(1, 2, 'mono8', 2, bytes([7, 200])))
    np.testing.assert_array_equal(mono, [[[7, 7, 7], [200, 200, 200]]])


def test_padded_rows_are_cut() -> None:
    """A step wider than the row (padding) is handled."""
    padded = np.zeros((2, 10), dtype=np.uint8)
    padded[:, :9] = RGB.reshape(2, 9)
    np.testing.assert_array_equal(decode_image(RawImage(2, 3, 'rgb8', 10, padded.tobytes())),
                                  RGB)


@pytest.mark.parametrize('encoding', ['16UC1', 'rgba8', 'bayer_rggb8', '32FC1'])
def test_other_encodings_are_refused_by_name(encoding: str) -> None:
    """An unsupported encoding raises an error naming it."""
    with pytest.raises(InputError, match=encoding):
        decode_image(RawImage(2, 3, encoding, 9, RGB.tobytes()))


def test_zero_size_and_truncated_raw_images_are_refused() -> None:
    """Empty images and data shorter than step * height raise."""
    with pytest.raises(InputError, match='empty'):
        decode_image(RawImage(0, 3, 'rgb8', 9, b''))
    with pytest.raises(InputError, match='do not hold the pixels'):
        decode_image(RawImage(2, 3, 'rgb8', 9, RGB.tobytes()[:-1]))


def _encoded(extension: str) -> bytes:
    image = np.full((8, 8, 3), (10, 120, 240), dtype=np.uint8)
    return cv2.imencode(extension, image[:, :, ::-1])[1].tobytes()


@pytest.mark.parametrize('fmt,extension', [('rgb8; jpeg compressed bgr8', '.jpg'),
                                           ('png', '.png'), ('jpeg', '.jpg')])
def test_compressed_jpeg_and_png_decode(fmt: str, extension: str) -> None:
    """Compressed jpeg and png decode to RGB (jpeg within its loss)."""
    rgb = decode_image(compressed(fmt, _encoded(extension)))
    assert rgb.shape == (8, 8, 3)
    assert np.abs(rgb.astype(int) - (10, 120, 240)).max() <= 4


def test_compressed_codec_parses_image_transport_formats() -> None:
    """Format strings name the codec; compressedDepth and others are refused by name."""
    assert compressed_codec('bgr8; jpeg compressed bgr8') == 'jpeg'
    assert compressed_codec('rgb8; png compressed rgb8') == 'png'
    assert compressed_codec('JPG') == 'jpeg'
    with pytest.raises(InputError, match='compressedDepth'):
        compressed_codec('16UC1; compressedDepth png')
    with pytest.raises(InputError, match='webp'):
        compressed_codec('rgb8; webp compressed rgb8')


def test_truncated_and_empty_compressed_data_are_refused() -> None:
    """A jpeg cut short (which OpenCV would half-decode) and empty data raise."""
    data = _encoded('.jpg')
    with pytest.raises(InputError, match='truncated'):
        decode_image(compressed('jpeg', data[: len(data) // 2]))
    with pytest.raises(InputError, match='empty'):
        decode_image(compressed('jpeg', b''))
    with pytest.raises(InputError, match='do not start like a png'):
        decode_image(compressed('png', data))
