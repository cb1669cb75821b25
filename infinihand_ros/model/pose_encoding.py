"""The 9-number camera pose encoding, written down in one place.

Layout (LingBot-Map / VGGT ``absT_quaR_FoV``): ``[t(3), q_xyzw(4), fov_h, fov_w]``.

- Direction: camera-to-world (``T_world_cam``), as LingBot-Map's stream and window stitching use
  it: ``t`` is the camera centre in the world frame and ``q`` rotates camera axes into the world
  (VGGT itself encodes world-to-camera; convert with ``invert_transform`` when using VGGT
  weights). To be checked against a real LingBot-Map checkpoint (MODEL_ANCHORS §8.4).
- Camera frame: OpenCV optical (x right, y down, z forward); world = first anchor camera.
- Quaternion in (x, y, z, w) order, not necessarily unit length in the raw output: decoding
  normalises it.
- FoV in radians, principal point at the image centre: fov_h = 2 atan((H/2)/fy),
  fov_w = 2 atan((W/2)/fx), with H, W the image size the encoding is decoded for.
"""

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
import numpy as np
import roma
import torch

POSE_ENCODING_SIZE = 9
TRANSLATION = slice(0, 3)
QUATERNION_XYZW = slice(3, 7)
FOV_H = 7
FOV_W = 8


def activate_pose(raw: torch.Tensor) -> torch.Tensor:
    """Return the camera head's output activation of raw encodings (..., 9).

    Translation and quaternion are linear; the two FoVs go through ReLU.
    """
    return torch.cat((raw[..., :FOV_H], torch.relu(raw[..., FOV_H:])), dim=-1)


def encoding_to_matrices(encoding: torch.Tensor, height: int, width: int
                         ) -> tuple[torch.Tensor, torch.Tensor]:
    """Decode encodings (..., 9) into camera-to-world (..., 4, 4) and intrinsics (..., 3, 3).

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


def encoding_to_camera(encoding: np.ndarray, height: int, width: int
                       ) -> tuple[CameraPose, Intrinsics]:
    """Decode one encoding (9,) into a ``CameraPose`` (camera-to-world) and ``Intrinsics``.

    Raises:
        InputError: for a wrong shape, a zero quaternion or a FoV outside (0, pi); the
            quaternion is normalised.

    """
    values = np.asarray(encoding, dtype=np.float64)
    if values.shape != (POSE_ENCODING_SIZE,):
        raise InputError(f'pose encoding: expected shape ({POSE_ENCODING_SIZE},), '
                         f'got {values.shape}')
    pose = CameraPose.from_quaternion(values[QUATERNION_XYZW], values[TRANSLATION])
    return pose, Intrinsics.from_fov(values[FOV_H], values[FOV_W], width, height)


def camera_to_encoding(pose: CameraPose, intrinsics: Intrinsics) -> np.ndarray:
    """Encode a camera-to-world pose and centred-principal-point intrinsics as (9,) float64."""
    fov_h, fov_w = intrinsics.fov()
    return np.concatenate((np.asarray(pose.translation, dtype=np.float64),
                           pose.quaternion_xyzw(), [fov_h, fov_w]))
