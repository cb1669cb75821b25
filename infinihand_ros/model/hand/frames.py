"""MANO global orientation and translation between frames, in torch (paper eqs. 6 and 9).

MANO rotates the hand about its rest root joint ``J0(betas)`` and then adds ``transl``. Mapping
every joint by ``x -> R x + t`` therefore gives ``Rot(orient') = R Rot(orient)`` and
``transl' = R (J0 + transl) + t - J0``; for the built-in hand ``J0 = 0`` and this is literally
eq. 6 (hand -> camera, ``R = R_h<-c^T``, ``t = 0``) and eq. 9 (camera -> world with the camera
pose ``T_world_cam``). Hand pose and betas do not change. The numpy twin used by the rest of the
project is ``core/mano_frames.transform_mano_params``.
"""

from infinihand_ros.core.errors import InputError
import roma
import torch


def _check(tensor: torch.Tensor, name: str, shape: tuple[int, ...]) -> None:
    """Raise InputError unless ``tensor`` has exactly ``shape``."""
    if tuple(tensor.shape) != shape:
        raise InputError(f'{name}: expected shape {shape}, got {tuple(tensor.shape)}')


def transform_orient_transl(global_orient: torch.Tensor, transl: torch.Tensor,
                            rotation: torch.Tensor, translation: torch.Tensor | None = None,
                            root_joint: torch.Tensor | None = None
                            ) -> tuple[torch.Tensor, torch.Tensor]:
    """Express MANO orientation and translation in another frame (``x -> R x + t``).

    Args:
        global_orient: (N, 3) axis-angle in the source frame, radians.
        transl: (N, 3) MANO translation in the source frame, metres.
        rotation: (N, 3, 3) rotation R from the source to the target frame.
        translation: (N, 3) translation t from the source to the target frame; zero if None.
        root_joint: (N, 3) rest root joint ``J0(betas)``; zero (the built-in hand) if None.

    Returns:
        (global_orient (N, 3), transl (N, 3)) in the target frame.

    Raises:
        InputError: for inconsistent shapes.

    """
    n = global_orient.shape[0]
    _check(global_orient, 'global_orient', (n, 3))
    _check(transl, 'transl', (n, 3))
    _check(rotation, 'rotation', (n, 3, 3))
    orient = roma.rotmat_to_rotvec(rotation @ roma.rotvec_to_rotmat(global_orient))
    root = torch.zeros_like(transl) if root_joint is None else root_joint
    _check(root, 'root_joint', (n, 3))
    moved = torch.einsum('nij,nj->ni', rotation, root + transl) - root
    if translation is not None:
        _check(translation, 'translation', (n, 3))
        moved = moved + translation
    return orient, moved


def hand_to_camera(global_orient_h: torch.Tensor, transl_h: torch.Tensor,
                   rotation_h_from_c: torch.Tensor, root_joint: torch.Tensor | None = None
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 6: crop-camera (hand) frame to the image camera frame.

    Args:
        global_orient_h: (N, 3) axis-angle in the crop-camera frame h.
        transl_h: (N, 3) MANO translation in h, metres.
        rotation_h_from_c: (N, 3, 3) ``R_h<-c`` (camera to crop camera; same optical centre).
        root_joint: (N, 3) rest root joint ``J0(betas)``; zero (built-in hand) if None.

    Returns:
        (global_orient_c (N, 3), transl_c (N, 3)) in the camera frame.

    """
    return transform_orient_transl(global_orient_h, transl_h,
                                   rotation_h_from_c.transpose(-1, -2), root_joint=root_joint)


def camera_to_world(global_orient_c: torch.Tensor, transl_c: torch.Tensor,
                    rotation_world_from_cam: torch.Tensor, camera_position: torch.Tensor,
                    root_joint: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 9: camera frame to the world frame with the camera pose ``T_world_cam``.

    Args:
        global_orient_c: (N, 3) axis-angle in the camera frame.
        transl_c: (N, 3) MANO translation in the camera frame, metres.
        rotation_world_from_cam: (N, 3, 3) camera-to-world rotation R_t.
        camera_position: (N, 3) camera centre in the world u_t, metres.
        root_joint: (N, 3) rest root joint ``J0(betas)``; zero (built-in hand) if None.

    Returns:
        (global_orient_w (N, 3), transl_w (N, 3)) in the world frame.

    """
    return transform_orient_transl(global_orient_c, transl_c, rotation_world_from_cam,
                                   camera_position, root_joint)
