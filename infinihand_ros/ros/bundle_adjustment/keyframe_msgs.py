"""Standard messages between the estimator and the bundle-adjustment node.

One keyframe travels as five messages with the keyframe's stamp, on relative topics under
``bundle_adjustment/keyframes/`` (remappable, namespace-aware): ``image`` (Image rgb8),
``depth`` (Image 32FC1, metres along the optical axis, NaN where unknown), ``hand_mask``
(Image mono8, 255 on hands), ``camera_info`` (the intrinsics) and ``pose`` (PoseStamped, the
metrically scaled raw ``T_world_cam``). The BA node answers on ``bundle_adjustment/corrections``
with a nav_msgs/Path per BA call: one pose per refined keyframe, stamped with the keyframe's
stamp, holding the rigid correction ``D = T_refined @ T_submitted^-1``, and publishes its status
(diagnostic_msgs/DiagnosticArray, the estimator's heartbeat of it) on
``bundle_adjustment/status``.

The parts may arrive in any order: ``KeyframeAssembler.add`` collects them by stamp and returns
the whole set once the last part is in. At most ``max_pending`` incomplete stamps are held;
when a new stamp would exceed that, the oldest incomplete one is dropped and counted.
"""

from collections import OrderedDict
from typing import Any, Final

from geometry_msgs.msg import Point
from geometry_msgs.msg import Pose
from geometry_msgs.msg import PoseStamped
from geometry_msgs.msg import Quaternion
from infinihand_ros.ba.corrections import Corrections
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.bag.camera_msgs import camera_info_to_intrinsics
from infinihand_ros.bag.camera_msgs import msg_to_image
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.errors import InputError
from infinihand_ros.ros import msg_builders
from nav_msgs.msg import Path
import numpy as np
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import CameraInfo
from sensor_msgs.msg import Image


class KeyframeAssembler:
    """Incomplete keyframes by stamp, oldest first (not thread-safe)."""

    def __init__(self, parts: tuple[str, ...], max_pending: int) -> None:
        """Collect sets of ``parts``; hold at most ``max_pending`` incomplete stamps.

        Raises:
            ValueError: for no parts or ``max_pending`` below 1.

        """
        if not parts or max_pending < 1:
            raise ValueError(f'KeyframeAssembler: need parts and max_pending >= 1, got '
                             f'{parts!r} and {max_pending}')
        self.parts = frozenset(parts)
        self.max_pending = max_pending
        self.dropped = 0
        self._pending: OrderedDict[int, dict[str, Any]] = OrderedDict()

    def __len__(self) -> int:
        """Return the number of incomplete stamps held."""
        return len(self._pending)

    def add(self, part: str, stamp_ns: int, msg: Any) -> dict[str, Any] | None:
        """Add one part; return every part of ``stamp_ns`` when this completed the set.

        A part given twice for one stamp keeps the newer message.

        Raises:
            ValueError: for a part name that is not one of ``parts``.

        """
        if part not in self.parts:
            raise ValueError(f'KeyframeAssembler: unknown part {part!r}; expected one of '
                             f'{sorted(self.parts)}')
        collected = self._pending.setdefault(stamp_ns, {})
        collected[part] = msg
        if collected.keys() == self.parts:
            return self._pending.pop(stamp_ns)
        while len(self._pending) > self.max_pending:
            self._pending.popitem(last=False)
            self.dropped += 1
        return None

    def clear(self) -> None:
        """Forget every incomplete stamp (not counted as dropped)."""
        self._pending.clear()


KEYFRAME_PREFIX: Final = 'bundle_adjustment/keyframes/'
IMAGE: Final = 'image'
DEPTH: Final = 'depth'
HAND_MASK: Final = 'hand_mask'
CAMERA_INFO: Final = 'camera_info'
POSE: Final = 'pose'
#: The parts of one keyframe and their message types.
KEYFRAME_PARTS: Final = {IMAGE: Image, DEPTH: Image, HAND_MASK: Image, CAMERA_INFO: CameraInfo,
                         POSE: PoseStamped}
#: Keyframes, corrections and status between the nodes: reliable, a few deep.
LINK_QOS: Final = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
CORRECTIONS_TOPIC: Final = 'bundle_adjustment/corrections'
STATUS_TOPIC: Final = 'bundle_adjustment/status'
#: Key of the BA worker's state among the status values (the estimator reads it).
STATE_KEY: Final = 'state'
MASK_ON: Final = 255


def _image_msg(stamp_ns: int, frame_id: str, pixels: np.ndarray, encoding: str,
               channels_bytes: int) -> Image:
    """Return an Image of contiguous (H, W[, C]) pixels."""
    height, width = pixels.shape[:2]
    return Image(header=msg_builders.header(stamp_ns, frame_id), height=height, width=width,
                 encoding=encoding, is_bigendian=0, step=width * channels_bytes,
                 data=np.ascontiguousarray(pixels).tobytes())


def keyframe_msgs(keyframe: KeyframeInput, world_frame_id: str, camera_frame_id: str
                  ) -> dict[str, Any]:
    """Return the five messages of a keyframe, keyed by part name."""
    stamp = keyframe.timestamp_ns
    mask = np.where(keyframe.hand_mask, MASK_ON, 0).astype(np.uint8)
    pose = CameraPose.from_matrix(keyframe.T_world_cam)
    return {
        IMAGE: _image_msg(stamp, camera_frame_id, keyframe.image, 'rgb8', 3),
        DEPTH: _image_msg(stamp, camera_frame_id, keyframe.depth.astype(np.float32), '32FC1',
                          4),
        HAND_MASK: _image_msg(stamp, camera_frame_id, mask, 'mono8', 1),
        CAMERA_INFO: msg_builders.camera_info_msg(stamp, camera_frame_id, keyframe.intrinsics),
        POSE: PoseStamped(header=msg_builders.header(stamp, world_frame_id),
                          pose=_pose(pose.rotation, pose.translation)),
    }


def _pose(rotation: np.ndarray, translation: np.ndarray) -> Pose:
    """Return a Pose of a rotation (3, 3) and a translation (3,)."""
    qx, qy, qz, qw = (float(v) for v in geometry.matrix_to_quaternion_xyzw(rotation))
    x, y, z = (float(v) for v in translation)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _matrix(pose: Any) -> np.ndarray:
    """Return the (4, 4) transform of a Pose (quaternion normalised).

    Raises:
        InputError: for non-finite values or a zero quaternion.

    """
    q, p = pose.orientation, pose.position
    return CameraPose.from_quaternion(np.array([q.x, q.y, q.z, q.w]),
                                      np.array([p.x, p.y, p.z])).matrix()


def _single_channel(msg: Any, encoding: str, dtype: type) -> np.ndarray:
    """Return the (H, W) pixels of a one-channel Image of ``encoding``.

    Raises:
        InputError: for another encoding, big-endian data, or data that does not fit the size.

    """
    if msg.encoding != encoding or msg.is_bigendian:
        raise InputError(f'keyframe image: expected little-endian {encoding}, got '
                         f'{msg.encoding!r} (big-endian: {bool(msg.is_bigendian)})')
    itemsize = np.dtype(dtype).itemsize
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if height == 0 or width == 0 or step < width * itemsize or data.size < step * height:
        raise InputError(f'keyframe {encoding} image {width}x{height}: step {step} and '
                         f'{data.size} bytes do not hold the pixels')
    rows = data[:step * height].reshape(height, step)[:, :width * itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(height, width)


def keyframe_from_msgs(parts: dict[str, Any], frame_id: int) -> KeyframeInput:
    """Return the BA input of a keyframe's five messages, under the id ``frame_id``.

    Raises:
        InputError: naming what is wrong (a missing part, mismatched stamps, an encoding, a
            size, a pose).

    """
    missing = sorted(set(KEYFRAME_PARTS) - set(parts))
    if missing:
        raise InputError(f'keyframe: missing part(s) {missing}')
    stamps = {name: ns_from_stamp(msg.header.stamp) for name, msg in parts.items()}
    if len(set(stamps.values())) != 1:
        raise InputError(f'keyframe: parts with different stamps {stamps}')
    return KeyframeInput(frame_id, stamps[IMAGE], msg_to_image(parts[IMAGE]),
                         _single_channel(parts[DEPTH], '32FC1', np.float32),
                         _matrix(parts[POSE].pose),
                         camera_info_to_intrinsics(parts[CAMERA_INFO]),
                         _single_channel(parts[HAND_MASK], 'mono8', np.uint8) > 0)


def corrections_msg(stamp_ns: int, frame_id: str, corrections: Corrections) -> Path:
    """Return the Path message of one BA call's corrections (stamped ``stamp_ns``)."""
    poses = [PoseStamped(header=msg_builders.header(int(time_ns), frame_id),
                         pose=_pose(matrix[:3, :3], matrix[:3, 3]))
             for time_ns, matrix in zip(corrections.times_ns, corrections.corrections)]
    return Path(header=msg_builders.header(stamp_ns, frame_id), poses=poses)


def corrections_from_msg(msg: Any) -> Corrections:
    """Return the corrections of a ``corrections_msg`` Path.

    Raises:
        InputError: for an empty path, repeated stamps or a pose that is not finite.

    """
    if not msg.poses:
        raise InputError('BA corrections: an empty path')
    times = np.array([ns_from_stamp(pose.header.stamp) for pose in msg.poses], dtype=np.int64)
    if len(np.unique(times)) != len(times):
        raise InputError('BA corrections: repeated keyframe stamps')
    return Corrections(times, np.stack([_matrix(pose.pose) for pose in msg.poses]))
