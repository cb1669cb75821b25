"""Dataclasses at the project's boundaries: intrinsics, camera pose, MANO params, hands, frames.

Units are metres, radians and nanosecond timestamps; the camera frame is OpenCV optical and poses
are camera-to-world (``T_world_cam``).
"""

from dataclasses import dataclass
from dataclasses import field
from dataclasses import replace
import math
import numbers

from infinihand_ros.core import geometry
from infinihand_ros.core.distortion import check_distortion
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import side_name
from infinihand_ros.core.validation import as_array
import numpy as np


@dataclass(frozen=True)
class Intrinsics:
    """Intrinsics of one image (pixels), principal point anywhere, with its lens distortion.

    Fields are coerced at construction: ``fx, fy, cx, cy`` to finite Python floats (from ints,
    floats or numpy scalars) and ``width, height`` to Python ints (from integral values).
    Strings, booleans, NaN, infinities, non-positive focal lengths and non-positive or
    fractional sizes raise ``InputError`` naming the field.

    ``distortion_model`` is None for a pinhole camera, else one of ``core.distortion``'s
    ``DISTORTION_MODELS`` (``plumb_bob``, ``rational_polynomial``, ``equidistant``) with its
    ``distortion`` coefficients in ROS / OpenCV order (coerced to a tuple of floats; the wrong
    count, a non-finite value or an unknown model raise ``InputError``; a polynomial model with
    all zeros is pinhole, model None). The coefficients act
    on normalised coordinates: a scaled or shifted image keeps them (only K changes).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion_model: str | None = None
    distortion: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        for name in ('fx', 'fy', 'cx', 'cy'):
            object.__setattr__(self, name, _finite_float(getattr(self, name), name))
        if self.fx <= 0 or self.fy <= 0:
            raise InputError(
                f'intrinsics: focal lengths must be positive, got fx={self.fx}, fy={self.fy}')
        for name in ('width', 'height'):
            object.__setattr__(self, name, _positive_int(getattr(self, name), name))
        model, coefficients = check_distortion(self.distortion_model, self.distortion)
        object.__setattr__(self, 'distortion_model', model)
        object.__setattr__(self, 'distortion', coefficients)

    @property
    def is_distorted(self) -> bool:
        """Return whether the lens bends rays (any model: zero polynomials are dropped)."""
        return self.distortion_model is not None

    def pinhole(self) -> 'Intrinsics':
        """Return the same K and size without distortion (the rectified image's intrinsics)."""
        return replace(self, distortion_model=None, distortion=())

    def with_matrix(self, fx: float, fy: float, cx: float, cy: float, width: int,
                    height: int) -> 'Intrinsics':
        """Return new K and size with this lens's distortion (a scaled or shifted image)."""
        return Intrinsics(fx, fy, cx, cy, width, height, self.distortion_model, self.distortion)

    @classmethod
    def from_matrix(cls, matrix: np.ndarray, width: int, height: int) -> 'Intrinsics':
        """Build from a 3x3 K and the image size in pixels."""
        k = as_array(matrix, 'intrinsics matrix K', (3, 3))
        return cls(float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), width, height)

    @classmethod
    def from_fov(cls, fov_h_rad: float, fov_w_rad: float, width: int, height: int) -> 'Intrinsics':
        """Build from vertical/horizontal FoV (radians) with the principal point at the centre."""
        fov_h_rad, fov_w_rad = _finite_float(fov_h_rad, 'fov_h_rad'), _finite_float(
            fov_w_rad, 'fov_w_rad')
        width, height = _positive_int(width, 'width'), _positive_int(height, 'height')
        if not (0.0 < fov_h_rad < np.pi and 0.0 < fov_w_rad < np.pi):
            raise InputError(
                f'field of view must be in (0, pi) radians, got h={fov_h_rad}, w={fov_w_rad}')
        return cls(float(geometry.focal_from_fov(fov_w_rad, width)),
                   float(geometry.focal_from_fov(fov_h_rad, height)),
                   width / 2.0, height / 2.0, width, height)

    def matrix(self) -> np.ndarray:
        """Return K as a float64 3x3 array."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def fov(self) -> tuple[float, float]:
        """Return (fov_h, fov_w) in radians, as in the model's pose encoding."""
        return (float(geometry.fov_from_focal(self.fy, self.height)),
                float(geometry.fov_from_focal(self.fx, self.width)))


def _finite_float(value: object, name: str) -> float:
    """Return an intrinsics field as a finite float or raise InputError naming it."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise InputError(f'intrinsics {name}: expected a number, got {value!r} '
                         f'({type(value).__name__}); pass an int or float')
    number = float(value)
    if not math.isfinite(number):
        raise InputError(f'intrinsics {name}: got {number}, which is NaN or infinite; '
                         'pass a finite number')
    return number


def _positive_int(value: object, name: str) -> int:
    """Return an image-size field as a positive int or raise InputError naming it."""
    integral = isinstance(value, numbers.Integral) or (
        isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer())
    if isinstance(value, (bool, np.bool_)) or not integral or not int(value) > 0:
        raise InputError(f'intrinsics {name}: image size must be a positive whole number of '
                         f'pixels, got {value!r}')
    return int(value)


@dataclass(frozen=True)
class CameraPose:
    """Camera-to-world pose ``T_world_cam``: ``p_world = rotation @ p_cam + translation``."""

    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        rot = as_array(self.rotation, 'camera rotation', (3, 3))
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-5) or np.linalg.det(rot) <= 0:
            raise InputError(
                'camera rotation: not a proper rotation matrix (R R^T != I or det <= 0)')
        object.__setattr__(self, 'rotation', rot)
        object.__setattr__(self, 'translation',
                           as_array(self.translation, 'camera translation', (3,)))

    @classmethod
    def identity(cls) -> 'CameraPose':
        """Return the world-frame camera (identity pose)."""
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> 'CameraPose':
        """Build from a 4x4 camera-to-world matrix."""
        mat = as_array(matrix, 'camera pose matrix', (4, 4))
        return cls(mat[:3, :3], mat[:3, 3])

    @classmethod
    def from_quaternion(cls, quaternion_xyzw: np.ndarray, translation: np.ndarray) -> 'CameraPose':
        """Build from an (x, y, z, w) quaternion and a translation in metres."""
        quat = as_array(quaternion_xyzw, 'camera quaternion (x, y, z, w)', (4,))
        if np.linalg.norm(quat) < 1e-9:
            raise InputError('camera quaternion: zero quaternion; pass a unit (x, y, z, w)')
        return cls(geometry.quaternion_xyzw_to_matrix(quat), translation)

    def matrix(self) -> np.ndarray:
        """Return the 4x4 camera-to-world matrix."""
        return geometry.make_transform(self.rotation, self.translation)

    def quaternion_xyzw(self) -> np.ndarray:
        """Return the rotation as an (x, y, z, w) quaternion with w >= 0."""
        return geometry.matrix_to_quaternion_xyzw(self.rotation)

    def inverse_matrix(self) -> np.ndarray:
        """Return ``T_cam_world`` as a 4x4 matrix."""
        return geometry.invert_transform(self.matrix())

    def to_world(self, points_cam: np.ndarray) -> np.ndarray:
        """Map camera-frame points (..., 3) to the world frame."""
        return np.asarray(points_cam) @ self.rotation.T + self.translation


@dataclass(frozen=True)
class ManoParams:
    """MANO parameters of one hand, in one frame (camera or world).

    Attributes:
        global_orient: (3,) axis-angle, radians.
        hand_pose: (15, 3) axis-angle per joint, relative to the flat hand.
        betas: (10,) shape coefficients.
        transl: (3,) translation, metres.

    """

    global_orient: np.ndarray
    hand_pose: np.ndarray
    betas: np.ndarray
    transl: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, 'global_orient',
                           as_array(self.global_orient, 'MANO global_orient', (3,)))
        object.__setattr__(self, 'hand_pose', as_array(
            self.hand_pose, 'MANO hand_pose', (NUM_HAND_POSE_JOINTS, 3)))
        object.__setattr__(self, 'betas', as_array(self.betas, 'MANO betas', (NUM_BETAS,)))
        object.__setattr__(self, 'transl', as_array(self.transl, 'MANO transl', (3,)))

    @classmethod
    def zeros(cls) -> 'ManoParams':
        """Return the flat mean hand at the origin."""
        return cls(np.zeros(3), np.zeros((NUM_HAND_POSE_JOINTS, 3)), np.zeros(NUM_BETAS),
                   np.zeros(3))


@dataclass(frozen=True)
class HandState:
    """One detected hand in one frame.

    Attributes:
        side: 0 left, 1 right.
        mano_cam: MANO parameters in the camera frame.
        joints_cam: (21, 3) joints in the camera frame, metres, OpenPose order.
        joints_2d: (21, 2) joints in image pixels; for a lens with distortion, the pixels of the
            image rectified to the pinhole camera with the same K (what the engine reads;
            ``core.distortion.distort_pixels`` maps them into the raw image).
        box_xyxy: (4,) box in pixels (x0, y0, x1, y1), in the same image as ``joints_2d``.
        confidence: presence score in [0, 1].
        mano_world: MANO parameters in the world frame, when the camera pose is known.
        joints_world: (21, 3) joints in the world frame, metres, when the camera pose is known.

    """

    side: int
    mano_cam: ManoParams
    joints_cam: np.ndarray
    joints_2d: np.ndarray
    box_xyxy: np.ndarray
    confidence: float
    mano_world: ManoParams | None = None
    joints_world: np.ndarray | None = None

    def __post_init__(self) -> None:
        side_name(self.side)
        object.__setattr__(self, 'joints_cam',
                           as_array(self.joints_cam, 'hand joints_cam', (NUM_JOINTS, 3)))
        object.__setattr__(self, 'joints_2d',
                           as_array(self.joints_2d, 'hand joints_2d', (NUM_JOINTS, 2)))
        object.__setattr__(self, 'box_xyxy', as_array(self.box_xyxy, 'hand box_xyxy', (4,)))
        if not 0.0 <= self.confidence <= 1.0:
            raise InputError(f'hand confidence must be in [0, 1], got {self.confidence}')
        if self.joints_world is not None:
            object.__setattr__(self, 'joints_world',
                               as_array(self.joints_world, 'hand joints_world', (NUM_JOINTS, 3)))


@dataclass(frozen=True)
class FrameResult:
    """Everything estimated for one input frame.

    Attributes:
        timestamp_ns: the source image's stamp (never the processing time).
        frame_index: 0-based index in the stream.
        camera_pose: camera-to-world pose in the world frame (the first anchor camera).
        intrinsics: the intrinsics used for this frame (given or predicted).
        hands: detected hands, at most one per side.
        is_keyframe: whether the frame entered the streaming memory.
        depth: (H, W) float32 depth in metres for keyframes, else None.
        metric_scale: factor applied to the model's camera translations (1.0 when unknown).
        raw_camera_pose: the estimator's pose before bundle-adjustment corrections, when BA
            corrected ``camera_pose``; None otherwise.
        pose_version: the engine's pose-track version ``camera_pose`` was computed with (it
            changes whenever the metric scale or BA corrections change; 0 for the first).
        hand_source: where the hands came from ('infinihand': the paper's hand branch;
            'mediapipe': MediaPipe Hands lifted to MANO).
        tracking: how the camera pose was found: 'tracked' (measured in the image),
            'predicted' (the network's motion: too little to track), 'reinitialised' (the
            track restarted here: a discontinuity, e.g. a cut) or 'static' (a fixed camera).
        ba_failed: the last bundle-adjustment call over this keyframe failed (the solver
            raised, the BA process died) or was rejected by its held-out check, so its pose
            lacks that refinement; set on the final trajectory (``StreamingEngine.refined``),
            False on live results.
        provisional_intrinsics: ``intrinsics`` is a provisional lens (a fixed camera's, while
            its lens is still being estimated beside the stream): hands placed with it are
            less certain.
        episode_refined: the pose carries the accepted whole-episode bundle adjustment of an
            offline run (``ba/episode.py``); set on the final trajectory, False otherwise.

    """

    timestamp_ns: int
    frame_index: int
    camera_pose: CameraPose
    intrinsics: Intrinsics
    hands: tuple[HandState, ...] = field(default_factory=tuple)
    is_keyframe: bool = False
    depth: np.ndarray | None = None
    metric_scale: float = 1.0
    raw_camera_pose: CameraPose | None = None
    pose_version: int = 0
    hand_source: str = 'infinihand'
    tracking: str = 'predicted'
    ba_failed: bool = False
    provisional_intrinsics: bool = False
    episode_refined: bool = False

    def __post_init__(self) -> None:
        sides = [hand.side for hand in self.hands]
        if len(sides) != len(set(sides)):
            raise InputError(f'frame {self.frame_index}: more than one hand per side ({sides})')

    def hand(self, side: int) -> HandState | None:
        """Return the hand of ``side`` or None when it was not detected."""
        return next((hand for hand in self.hands if hand.side == side), None)
