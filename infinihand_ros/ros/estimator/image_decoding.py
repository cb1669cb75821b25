"""Image and CompressedImage messages to the core's RGB uint8 images, refusing bad frames.

Raw images go through ``bag.camera_msgs.msg_to_image`` (rgb8, bgr8, mono8; other encodings,
empty images and data shorter than ``step * height`` raise ``InputError`` naming the problem).
Compressed images must be jpeg or png (image_transport's ``compressed`` plugin); their format
string is checked first (``compressedDepth`` and other codecs are refused by name) and the
bytes must be complete (start and end markers of the codec), because OpenCV silently decodes a
truncated JPEG into a partly grey image. Decoding is ``bag.camera_msgs.compressed_msg_to_image``.
"""

from typing import Final

from infinihand_ros.bag.camera_msgs import CODEC_EXTENSIONS
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.camera_msgs import msg_to_image
from infinihand_ros.core.errors import InputError
import numpy as np
from sensor_msgs.msg import CompressedImage
from sensor_msgs.msg import Image

#: First and last bytes of a complete file of each codec.
JPEG_START: Final = b'\xff\xd8'
JPEG_END: Final = b'\xff\xd9'
PNG_START: Final = b'\x89PNG\r\n\x1a\n'
PNG_END: Final = b'IEND\xaeB`\x82'
_MARKERS: Final = {'jpeg': (JPEG_START, JPEG_END), 'png': (PNG_START, PNG_END)}


def compressed_codec(fmt: str) -> str:
    """Return the codec ('jpeg' or 'png') a CompressedImage ``format`` string names.

    Accepts image_transport's ``'<encoding>; <codec> compressed <encoding>'`` and the bare
    ``'jpeg'`` / ``'png'`` (``'jpg'`` too) some drivers send.

    Raises:
        InputError: naming the format for any other codec (e.g. ``compressedDepth``).

    """
    words = fmt.replace(';', ' ').lower().split()
    codecs = {'jpg': 'jpeg', 'jpeg': 'jpeg', 'png': 'png'}
    named = [codecs[word] for word in words if word in codecs]
    if 'compresseddepth' in words or len(set(named)) != 1:
        raise InputError(f'compressed image format {fmt!r} is not supported; publish '
                         f"{sorted(CODEC_EXTENSIONS)} through image_transport's compressed "
                         'plugin')
    return named[0]


def check_complete(data: bytes, codec: str) -> None:
    """Raise InputError unless ``data`` starts and ends like a complete ``codec`` file."""
    start, end = _MARKERS[codec]
    if not data.startswith(start):
        raise InputError(f'compressed image: {len(data)} bytes that do not start like a '
                         f'{codec} file')
    if not data.rstrip(b'\x00').endswith(end):
        raise InputError(f'compressed image: {codec} data of {len(data)} bytes is truncated '
                         '(no end marker)')


def decode_compressed(msg: CompressedImage) -> np.ndarray:
    """Decode a CompressedImage message to (H, W, 3) uint8 RGB.

    Raises:
        InputError: for an unsupported format, empty, truncated or undecodable data.

    """
    codec = compressed_codec(str(msg.format))
    data = bytes(memoryview(msg.data))
    if not data:
        raise InputError(f'compressed image ({msg.format!r}) is empty')
    check_complete(data, codec)
    return compressed_msg_to_image(msg)


def decode_image(msg: Image | CompressedImage) -> np.ndarray:
    """Decode an Image or a CompressedImage message to (H, W, 3) uint8 RGB.

    Raises:
        InputError: naming what is wrong (encoding, size, truncation, codec).

    """
    if hasattr(msg, 'format'):
        return decode_compressed(msg)
    return msg_to_image(msg)
