"""Conversions between the core dataclasses and our bag messages (rosbags message objects).

``*_to_msg`` functions build message objects from a typestore made by
``typestore.build_typestore()``; ``msg_to_*`` functions accept any object with the message's
fields (rosbags objects from any typestore, e.g. the one an ``AnyReader`` builds from a bag).
float64 fields round-trip exactly; float32 fields (hand confidence, 2D joints, boxes) within
float32 precision; rotations through (x, y, z, w) quaternions to within about 1e-15.
"""

from dataclasses import dataclass
from typing import Any, Final

from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import HAND_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import KEYFRAME_POSES_MSG
from infinihand_ros.bag.typestore import MANO_PARAMETERS_MSG
from infinihand_ros.bag.typestore import POINT_MSG
from infinihand_ros.bag.typestore import POSE_MSG
from infinihand_ros.bag.typestore import QUATERNION_MSG
from infinihand_ros.bag.typestore import TIME_MSG
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.units import NS_PER_S
import numpy as np
from rosbags.typesys.store import Typestore

#: Range of builtin_interfaces/Time.sec (int32).
STAMP_SEC_MIN: Final = -(2 ** 31)
STAMP_SEC_MAX: Final = 2 ** 31 - 1
#: Largest value of a uint32 message field (frame indices).
UINT32_MAX: Final = 2 ** 32 - 1
#: Shape of the row-major K in HandFrame.k.
K_SHAPE: Final = (3, 3)

#: rosbags message objects are generated dataclasses without a common base class.
Msg = Any


@dataclass(frozen=True)
class KeyframePoseUpdate:
    """One bundle-adjustment update of keyframe poses (the content of a KeyframePoses message).

    Attributes:
        frame_indices: 0-based stream index of each keyframe.
        stamps_ns: source image stamp of each keyframe, nanoseconds.
        poses: refined ``T_world_cam`` of each keyframe.
        initial_cost: BA cost before optimisation.
        final_cost: BA cost after optimisation.
        num_iterations: optimiser iterations run.
        converged: whether the optimiser reported convergence.

    """

    frame_indices: tuple[int, ...]
    stamps_ns: tuple[int, ...]
    poses: tuple[CameraPose, ...]
    initial_cost: float = 0.0
    final_cost: float = 0.0
    num_iterations: int = 0
    converged: bool = False

    def __post_init__(self) -> None:
        """Check the three sequences are parallel and store them as tuples."""
        lengths = (len(self.frame_indices), len(self.stamps_ns), len(self.poses))
        if len(set(lengths)) != 1:
            raise InputError(
                f'keyframe pose update: frame_indices, stamps_ns and poses must have the same '
                f'length, got {lengths}')
        object.__setattr__(self, 'frame_indices', tuple(int(i) for i in self.frame_indices))
        object.__setattr__(self, 'stamps_ns', tuple(int(s) for s in self.stamps_ns))
        object.__setattr__(self, 'poses', tuple(self.poses))


def _msg_class(typestore: Typestore, typename: str) -> type:
    """Return the message class of ``typename`` in ``typestore``."""
    try:
        return typestore.types[typename]
    except KeyError as exc:
        raise ConfigError(f'typestore has no message type {typename}; build it with '
                          f'infinihand_ros.bag.typestore.build_typestore()') from exc


def _check_type(msg: Msg, typename: str) -> None:
    """Raise InputError when ``msg`` is a rosbags message of another type than ``typename``."""
    got = getattr(msg, '__msgtype__', None)
    if got is not None and got != typename:
        raise InputError(f'expected a {typename} message, got {got}')


def _check_uint32(value: int, name: str) -> int:
    """Return ``value`` as an int after checking it fits a uint32 message field."""
    if not 0 <= int(value) <= UINT32_MAX:
        raise InputError(f'{name} must be in [0, {UINT32_MAX}] to fit a uint32 field, got {value}')
    return int(value)


def _reshaped(values: object, shape: tuple[int, ...], name: str) -> np.ndarray:
    """Return a message array as float64 of ``shape``, raising InputError on a size mismatch."""
    array = np.asarray(values, dtype=np.float64)
    if array.size != int(np.prod(shape)):
        raise InputError(f'{name} must hold {int(np.prod(shape))} values (reshaped to {shape}), '
                         f'got {array.size}')
    return array.reshape(shape)


def stamp_from_ns(typestore: Typestore, timestamp_ns: int) -> Msg:
    """Convert a timestamp in nanoseconds to a builtin_interfaces/msg/Time.

    Args:
        typestore: typestore holding the standard types.
        timestamp_ns: nanoseconds since the epoch (negative allowed: nanosec stays in [0, 1e9)).

    Raises:
        InputError: when the seconds do not fit the int32 ``sec`` field.

    """
    sec, nanosec = divmod(int(timestamp_ns), NS_PER_S)
    if not STAMP_SEC_MIN <= sec <= STAMP_SEC_MAX:
        raise InputError(f'timestamp {timestamp_ns} ns is outside the int32 seconds range of '
                         f'builtin_interfaces/Time; pass nanoseconds since the epoch')
    return _msg_class(typestore, TIME_MSG)(sec=sec, nanosec=nanosec)


def ns_from_stamp(stamp: Msg) -> int:
    """Convert a builtin_interfaces/msg/Time (``sec``, ``nanosec``) to nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def _header(typestore: Typestore, timestamp_ns: int, frame_id: str) -> Msg:
    """Build a std_msgs/msg/Header."""
    return _msg_class(typestore, HEADER_MSG)(
        stamp=stamp_from_ns(typestore, timestamp_ns), frame_id=str(frame_id))


def _pose_msg(typestore: Typestore, position: np.ndarray, quaternion_xyzw: np.ndarray) -> Msg:
    """Build a geometry_msgs/msg/Pose from a position (m) and an (x, y, z, w) quaternion."""
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion_xyzw)
    point = _msg_class(typestore, POINT_MSG)(x=x, y=y, z=z)
    quaternion = _msg_class(typestore, QUATERNION_MSG)(x=qx, y=qy, z=qz, w=qw)
    return _msg_class(typestore, POSE_MSG)(position=point, orientation=quaternion)


def pose_to_msg(typestore: Typestore, pose: CameraPose) -> Msg:
    """Convert a ``T_world_cam`` to a geometry_msgs/msg/Pose (position = camera centre, m)."""
    return _pose_msg(typestore, pose.translation, pose.quaternion_xyzw())


def msg_to_pose(msg: Msg) -> CameraPose:
    """Convert a geometry_msgs/msg/Pose to a CameraPose (the quaternion is normalised).

    Raises:
        InputError: when the orientation is the zero quaternion or a value is not finite.

    """
    _check_type(msg, POSE_MSG)
    position, orientation = msg.position, msg.orientation
    return CameraPose.from_quaternion(
        np.array([orientation.x, orientation.y, orientation.z, orientation.w]),
        np.array([position.x, position.y, position.z]))


def _points_to_msgs(typestore: Typestore, points: np.ndarray) -> list[Msg]:
    """Convert (N, 3) points in metres to geometry_msgs/msg/Point objects."""
    point_class = _msg_class(typestore, POINT_MSG)
    return [point_class(x=float(x), y=float(y), z=float(z)) for x, y, z in points]


def _msgs_to_points(msgs: list[Msg]) -> np.ndarray:
    """Convert geometry_msgs/msg/Point objects to an (N, 3) float64 array."""
    return np.array([[point.x, point.y, point.z] for point in msgs], dtype=np.float64)


def mano_to_msg(typestore: Typestore, params: ManoParams) -> Msg:
    """Convert ManoParams to an infinihand_msgs/msg/ManoParameters (float64, exact)."""
    return _msg_class(typestore, MANO_PARAMETERS_MSG)(
        global_orient=np.array(params.global_orient, dtype=np.float64),
        hand_pose=np.array(params.hand_pose, dtype=np.float64).reshape(-1),
        betas=np.array(params.betas, dtype=np.float64),
        transl=np.array(params.transl, dtype=np.float64))


def msg_to_mano(msg: Msg) -> ManoParams:
    """Convert an infinihand_msgs/msg/ManoParameters to ManoParams.

    Raises:
        InputError: when an array has the wrong length or holds NaN/inf.

    """
    _check_type(msg, MANO_PARAMETERS_MSG)
    return ManoParams(
        global_orient=np.asarray(msg.global_orient, dtype=np.float64),
        hand_pose=_reshaped(msg.hand_pose, (NUM_HAND_POSE_JOINTS, 3), 'ManoParameters.hand_pose'),
        betas=np.asarray(msg.betas, dtype=np.float64),
        transl=np.asarray(msg.transl, dtype=np.float64))


def hand_to_msg(typestore: Typestore, hand: HandState) -> Msg:
    """Convert a HandState to an infinihand_msgs/msg/Hand.

    World fields are filled when the hand has both ``mano_world`` and ``joints_world``; the
    wrist pose is then ``joints_world[0]`` with the orientation of ``mano_world.global_orient``.
    The wrist-frame fields are ``core.output_fields.hand_output``'s (the estimator's /tf wrist
    frame and its wrist-frame landmarks) where it can form them.

    Raises:
        InputError: when exactly one of ``mano_world`` and ``joints_world`` is set.

    """
    has_mano_world, has_joints_world = hand.mano_world is not None, hand.joints_world is not None
    if has_mano_world != has_joints_world:
        raise InputError(
            f'hand side {hand.side}: mano_world is {"set" if has_mano_world else "None"} but '
            f'joints_world is {"set" if has_joints_world else "None"}; set both or neither')
    if has_mano_world:
        mano_world, joints_world = hand.mano_world, hand.joints_world
        wrist_quaternion = geometry.matrix_to_quaternion_xyzw(
            geometry.axis_angle_to_matrix(mano_world.global_orient))
        wrist_pose = _pose_msg(typestore, joints_world[WRIST], wrist_quaternion)
    else:
        mano_world, joints_world = ManoParams.zeros(), np.zeros((NUM_JOINTS, 3))
        wrist_pose = pose_to_msg(typestore, CameraPose.identity())
    output = hand_output(hand) if has_mano_world else None
    if output is None:
        wrist_frame = pose_to_msg(typestore, CameraPose.identity())
        joints_wrist = np.zeros((NUM_JOINTS, 3))
    else:
        wrist_frame = _pose_msg(typestore, output.wrist_pose.position,
                                output.wrist_pose.orientation_xyzw)
        joints_wrist = output.wrist_frame_landmarks
    return _msg_class(typestore, HAND_MSG)(
        side=int(hand.side),
        confidence=float(hand.confidence),
        mano_camera=mano_to_msg(typestore, hand.mano_cam),
        mano_world=mano_to_msg(typestore, mano_world),
        has_world=has_mano_world,
        joints_camera=_points_to_msgs(typestore, hand.joints_cam),
        joints_world=_points_to_msgs(typestore, joints_world),
        joints_2d=np.asarray(hand.joints_2d, dtype=np.float32).reshape(-1),
        box_xyxy=np.asarray(hand.box_xyxy, dtype=np.float32),
        wrist_pose_world=wrist_pose,
        has_wrist_frame=output is not None,
        wrist_frame_world=wrist_frame,
        joints_wrist=_points_to_msgs(typestore, joints_wrist))


def msg_to_hand(msg: Msg) -> HandState:
    """Convert an infinihand_msgs/msg/Hand to a HandState (the derived wrist fields are not read).

    Raises:
        InputError: on an unknown side, a confidence outside [0, 1] or arrays of the wrong size.

    """
    _check_type(msg, HAND_MSG)
    if int(msg.side) not in SIDES:
        raise InputError(f'Hand message: side must be 0 (LEFT) or 1 (RIGHT), got {msg.side}')
    return HandState(
        side=int(msg.side),
        mano_cam=msg_to_mano(msg.mano_camera),
        joints_cam=_msgs_to_points(msg.joints_camera),
        joints_2d=_reshaped(msg.joints_2d, (NUM_JOINTS, 2), 'Hand.joints_2d'),
        box_xyxy=np.asarray(msg.box_xyxy, dtype=np.float64),
        confidence=float(msg.confidence),
        mano_world=msg_to_mano(msg.mano_world) if msg.has_world else None,
        joints_world=_msgs_to_points(msg.joints_world) if msg.has_world else None)


def frame_result_to_msg(typestore: Typestore, result: FrameResult, frame_id: str) -> Msg:
    """Convert a FrameResult to an infinihand_msgs/msg/HandFrame (the depth map is not stored).

    Args:
        typestore: typestore from ``build_typestore()``.
        result: the frame's estimates.
        frame_id: name of the world frame, written to ``header.frame_id``.

    Raises:
        InputError: when the stamp or frame index does not fit the message fields, or a hand is
            inconsistent (see ``hand_to_msg``).
        ConfigError: when ``typestore`` lacks our message types.

    """
    intrinsics = result.intrinsics
    return _msg_class(typestore, HAND_FRAME_MSG)(
        header=_header(typestore, result.timestamp_ns, frame_id),
        frame_index=_check_uint32(result.frame_index, 'frame_index'),
        camera_pose=pose_to_msg(typestore, result.camera_pose),
        k=intrinsics.matrix().reshape(-1),
        intrinsics_provisional=bool(result.provisional_intrinsics),
        width=_check_uint32(intrinsics.width, 'image width'),
        height=_check_uint32(intrinsics.height, 'image height'),
        metric_scale=float(result.metric_scale),
        is_keyframe=bool(result.is_keyframe),
        tracking=str(result.tracking),
        hands=[hand_to_msg(typestore, hand) for hand in result.hands])


def msg_to_frame_result(msg: Msg) -> FrameResult:
    """Convert an infinihand_msgs/msg/HandFrame to a FrameResult (``depth`` is None).

    Raises:
        InputError: when the message is of another type or holds invalid values.

    """
    _check_type(msg, HAND_FRAME_MSG)
    k = _reshaped(msg.k, K_SHAPE, 'HandFrame.k')
    return FrameResult(
        timestamp_ns=ns_from_stamp(msg.header.stamp),
        frame_index=int(msg.frame_index),
        camera_pose=msg_to_pose(msg.camera_pose),
        intrinsics=Intrinsics.from_matrix(k, int(msg.width), int(msg.height)),
        hands=tuple(msg_to_hand(hand) for hand in msg.hands),
        is_keyframe=bool(msg.is_keyframe),
        metric_scale=float(msg.metric_scale),
        # Fields absent (HandFrames of the earlier definition) or left empty: the defaults.
        tracking=str(getattr(msg, 'tracking', '') or FrameResult.tracking),
        provisional_intrinsics=bool(getattr(msg, 'intrinsics_provisional', False)))


def keyframe_poses_to_msg(typestore: Typestore, update: KeyframePoseUpdate, frame_id: str,
                          stamp_ns: int | None = None) -> Msg:
    """Convert a KeyframePoseUpdate to an infinihand_msgs/msg/KeyframePoses.

    Args:
        typestore: typestore from ``build_typestore()``.
        update: the refined keyframe poses.
        frame_id: name of the world frame, written to ``header.frame_id``.
        stamp_ns: header stamp; the newest keyframe stamp when None.

    Raises:
        InputError: when ``update`` is empty and no ``stamp_ns`` is given, or a value does not
            fit its field.

    """
    if stamp_ns is None:
        if not update.stamps_ns:
            raise InputError('keyframe pose update is empty: pass stamp_ns for the header')
        stamp_ns = max(update.stamps_ns)
    return _msg_class(typestore, KEYFRAME_POSES_MSG)(
        header=_header(typestore, stamp_ns, frame_id),
        frame_indices=np.array(
            [_check_uint32(i, 'keyframe index') for i in update.frame_indices], dtype=np.uint32),
        stamps=[stamp_from_ns(typestore, stamp) for stamp in update.stamps_ns],
        poses=[pose_to_msg(typestore, pose) for pose in update.poses],
        initial_cost=float(update.initial_cost),
        final_cost=float(update.final_cost),
        num_iterations=_check_uint32(update.num_iterations, 'num_iterations'),
        converged=bool(update.converged))


def msg_to_keyframe_poses(msg: Msg) -> KeyframePoseUpdate:
    """Convert an infinihand_msgs/msg/KeyframePoses to a KeyframePoseUpdate.

    Raises:
        InputError: when the message is of another type, its arrays differ in length, or a
            pose is invalid.

    """
    _check_type(msg, KEYFRAME_POSES_MSG)
    return KeyframePoseUpdate(
        frame_indices=tuple(int(i) for i in msg.frame_indices),
        stamps_ns=tuple(ns_from_stamp(stamp) for stamp in msg.stamps),
        poses=tuple(msg_to_pose(pose) for pose in msg.poses),
        initial_cost=float(msg.initial_cost),
        final_cost=float(msg.final_cost),
        num_iterations=int(msg.num_iterations),
        converged=bool(msg.converged))
