"""The 9-number camera pose encoding and its direction, written down in one place.

Layout (LingBot-Map / VGGT ``absT_quaR_FoV``): ``[t(3), q_xyzw(4), fov_h, fov_w]``.

- The raw encoding holds one rigid transform ``[R | t]`` (``R`` from the quaternion ``q``).
  Which way it points is a property of the weights, recorded in each checkpoint's geometry
  config as ``pose_direction``:

  - ``cam_to_world``: ``[R | t] = T_world_cam``; ``t`` is the camera centre in the world and
    ``R`` turns camera axes into world axes. Our own (tiny, seeded, trained) checkpoints.
  - ``world_to_cam``: ``[R | t] = T_cam_world`` (OpenCV extrinsics, "camera from world").

  Everything downstream (engine, BA, world placement) only ever sees camera-to-world: decode
  with ``encoding_to_cam_to_world`` and encode ground truth with ``cam_to_world_to_encoding``
  (torch) or ``camera_to_encoding`` (numpy), always passing the checkpoint's direction.

- Upstream evidence (LingBot-Map and VGGT sources, read 2026; file and function names):

  - VGGT is ``world_to_cam``: ``vggt/utils/pose_enc.py`` (``extri_intri_to_pose_encoding``,
    ``pose_encoding_to_extri_intri``) documents the matrix as "camera from world", and VGGT's
    README says "following OpenCV convention (camera from world)".
  - LingBot-Map copies those docstrings (``lingbot_map/utils/pose_enc.py``) and its ``demo.py``
    ``postprocess`` inverts the decoded matrix under the comment "Convert w2c to c2w", which
    reads as ``world_to_cam``. Its working code says the opposite: ``demo.py``
    ``export_raw_ply`` unprojects depth with that inverted matrix through
    ``lingbot_map/utils/geometry.py`` ``depth_to_world_coords_points``, which takes
    camera-from-world and inverts it again, so world points come out as ``[R | t] @ p_cam``,
    which is right only if the raw matrix is camera-to-world. The window stitching
    (``lingbot_map/models/gct_stream_window.py`` ``_warp_predictions``) composes ``R_ab @ R``
    and moves ``t`` as a camera centre, and the README calls the stage-1 weights "(c2w)" when
    loaded into VGGT. So the converter records ``cam_to_world`` for LingBot-Map and
    ``world_to_cam`` for VGGT (``model/io/convert_lingbot_map.py``, ``UPSTREAM_POSE_DIRECTION``;
    ``--pose-direction`` overrides it). Check it on a real checkpoint before relying on it:
    the first frame decodes to about identity either way, but only the right direction makes
    the depth of several frames unproject into one consistent point cloud.

- Camera frame: OpenCV optical (x right, y down, z forward); world = first anchor camera.
- The raw quaternion is (x, y, z, w) and need not be unit length: decoding normalises it.
- FoV in radians, principal point at the image centre ``(W/2, H/2)`` as upstream decodes it:
  fov_h = 2 atan((H/2)/fy), fov_w = 2 atan((W/2)/fx), with H, W the model input size.
"""

from typing import Final

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
import numpy as np
import roma
import torch

POSE_ENCODING_SIZE: Final = 9
TRANSLATION: Final = slice(0, 3)
QUATERNION_XYZW: Final = slice(3, 7)
FOV_H: Final = 7
FOV_W: Final = 8
#: Values of ``GeometryConfig.pose_direction``.
CAM_TO_WORLD: Final = 'cam_to_world'
WORLD_TO_CAM: Final = 'world_to_cam'
POSE_DIRECTIONS: Final = (CAM_TO_WORLD, WORLD_TO_CAM)


def check_pose_direction(direction: str) -> str:
    """Return ``direction`` if it is one of ``POSE_DIRECTIONS``.

    Raises:
        ValueError: naming the value and the valid ones.

    """
    if direction not in POSE_DIRECTIONS:
        raise ValueError(f'pose_direction must be one of {list(POSE_DIRECTIONS)}, '
                         f'got {direction!r}')
    return direction


def activate_pose(raw: torch.Tensor) -> torch.Tensor:
    """Return the camera head's output activation of raw encodings (..., 9).

    Translation and quaternion are linear; the two FoVs go through ReLU.
    """
    return torch.cat((raw[..., :FOV_H], torch.relu(raw[..., FOV_H:])), dim=-1)


def encoding_to_matrices(encoding: torch.Tensor, height: int, width: int
                         ) -> tuple[torch.Tensor, torch.Tensor]:
    """Decode encodings (..., 9) into the raw ``[R | t]`` (..., 4, 4) and intrinsics (..., 3, 3).

    The transform points the way the checkpoint's ``pose_direction`` says; use
    ``encoding_to_cam_to_world`` unless you need the raw matrix.

    Args:
        encoding: pose encodings in the layout above.
        height: image height in pixels the FoVs refer to.
        width: image width in pixels.

    """
    rotation = roma.unitquat_to_rotmat(torch.nn.functional.normalize(
        encoding[..., QUATERNION_XYZW], dim=-1))
    transform = torch.zeros(*encoding.shape[:-1], 4, 4, dtype=encoding.dtype,
                            device=encoding.device)
    transform[..., :3, :3] = rotation
    transform[..., :3, 3] = encoding[..., TRANSLATION]
    transform[..., 3, 3] = 1.0
    intrinsics = torch.zeros(*encoding.shape[:-1], 3, 3, dtype=encoding.dtype,
                             device=encoding.device)
    intrinsics[..., 0, 0] = (width / 2.0) / torch.tan(encoding[..., FOV_W] / 2.0)
    intrinsics[..., 1, 1] = (height / 2.0) / torch.tan(encoding[..., FOV_H] / 2.0)
    intrinsics[..., 0, 2] = width / 2.0
    intrinsics[..., 1, 2] = height / 2.0
    intrinsics[..., 2, 2] = 1.0
    return transform, intrinsics


def invert_rigid(transform: torch.Tensor) -> torch.Tensor:
    """Return the inverse of rigid transforms (..., 4, 4): ``[R^T | -R^T t]``."""
    rotation_t = transform[..., :3, :3].transpose(-1, -2)
    inverse = torch.zeros_like(transform)
    inverse[..., :3, :3] = rotation_t
    inverse[..., :3, 3] = -(rotation_t @ transform[..., :3, 3:4])[..., 0]
    inverse[..., 3, 3] = 1.0
    return inverse


def encoding_to_cam_to_world(encoding: torch.Tensor, height: int, width: int, direction: str
                             ) -> tuple[torch.Tensor, torch.Tensor]:
    """Decode encodings (..., 9) into camera-to-world poses and intrinsics, whatever the weights.

    Args:
        encoding: pose encodings in the layout above (e.g. ``GeometryOutput.pose_encoding``).
        height: model input height in pixels the FoVs refer to.
        width: model input width in pixels.
        direction: the checkpoint's ``GeometryConfig.pose_direction``.

    Returns:
        ``T_world_cam`` (..., 4, 4) (OpenCV camera, world = first anchor camera, model units)
        and the model-size intrinsics K (..., 3, 3) in pixels, same dtype and device.

    Raises:
        ValueError: for an unknown ``direction``.

    """
    transform, intrinsics = encoding_to_matrices(encoding, height, width)
    if check_pose_direction(direction) == WORLD_TO_CAM:
        transform = invert_rigid(transform)
    return transform, intrinsics


def cam_to_world_to_encoding(cam_to_world: torch.Tensor, intrinsics: torch.Tensor,
                             height: int, width: int, direction: str) -> torch.Tensor:
    """Encode camera-to-world poses and intrinsics as (..., 9), e.g. ground truth for training.

    The inverse of ``encoding_to_cam_to_world`` (the quaternion comes out unit, w >= 0).

    Args:
        cam_to_world: ``T_world_cam`` (..., 4, 4), rotation part orthonormal.
        intrinsics: (..., 3, 3) K in pixels of the model input (only fx, fy are used).
        height: model input height in pixels.
        width: model input width in pixels.
        direction: the ``pose_direction`` the network is trained for.

    Raises:
        ValueError: for an unknown ``direction``.

    """
    transform = cam_to_world
    if check_pose_direction(direction) == WORLD_TO_CAM:
        transform = invert_rigid(cam_to_world)
    quaternion = roma.rotmat_to_unitquat(transform[..., :3, :3])
    quaternion = torch.where(quaternion[..., 3:] < 0, -quaternion, quaternion)
    fov_h = 2.0 * torch.atan((height / 2.0) / intrinsics[..., 1, 1])
    fov_w = 2.0 * torch.atan((width / 2.0) / intrinsics[..., 0, 0])
    return torch.cat((transform[..., :3, 3], quaternion, fov_h[..., None], fov_w[..., None]),
                     dim=-1)


def encoding_to_camera(encoding: np.ndarray, height: int, width: int,
                       direction: str = CAM_TO_WORLD) -> tuple[CameraPose, Intrinsics]:
    """Decode one encoding (9,) into a camera-to-world ``CameraPose`` and ``Intrinsics``.

    Args:
        encoding: one pose encoding in the layout above.
        height: image height in pixels the FoVs refer to.
        width: image width in pixels.
        direction: the checkpoint's ``pose_direction`` (default: ours).

    Raises:
        InputError: for a wrong shape, a zero quaternion or a FoV outside (0, pi); the
            quaternion is normalised.
        ValueError: for an unknown ``direction``.

    """
    values = np.asarray(encoding, dtype=np.float64)
    if values.shape != (POSE_ENCODING_SIZE,):
        raise InputError(f'pose encoding: expected shape ({POSE_ENCODING_SIZE},), '
                         f'got {values.shape}')
    pose = CameraPose.from_quaternion(values[QUATERNION_XYZW], values[TRANSLATION])
    if check_pose_direction(direction) == WORLD_TO_CAM:
        pose = CameraPose.from_matrix(pose.inverse_matrix())
    return pose, Intrinsics.from_fov(values[FOV_H], values[FOV_W], width, height)


def camera_to_encoding(pose: CameraPose, intrinsics: Intrinsics,
                       direction: str = CAM_TO_WORLD) -> np.ndarray:
    """Encode a camera-to-world pose and its intrinsics as (9,) float64.

    Args:
        pose: ``T_world_cam``.
        intrinsics: the image's intrinsics (only the FoVs are kept: principal point assumed
            at the centre).
        direction: the ``pose_direction`` to encode for (default: ours).

    Raises:
        ValueError: for an unknown ``direction``.

    """
    if check_pose_direction(direction) == WORLD_TO_CAM:
        pose = CameraPose.from_matrix(pose.inverse_matrix())
    fov_h, fov_w = intrinsics.fov()
    return np.concatenate((np.asarray(pose.translation, dtype=np.float64),
                           pose.quaternion_xyzw(), [fov_h, fov_w]))
