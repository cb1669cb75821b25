"""Random left-right mirroring of whole training clips (ours).

The bundled model finds right hands more often than left ones on held-out sequences (0.83 vs
0.79), and a left hand it missed was found as a right one (probability 0.99) once the frame was
mirrored. Mirroring a clip turns every left hand into a right one and back, and is an exact
symmetry of the task, so it doubles what the mask head sees of each side.

A mirrored clip is the same scene reflected through the camera's x = 0 plane,
``M = diag(-1, 1, 1)`` (``mano/mirror.py``), with the world reflected by the same ``M``:

- images, masks and depth: columns reversed (``u -> W - 1 - u``, pixel centres at integers),
  masks' side channels swapped;
- every per-side target: sides swapped; camera and world joints mirrored (``x -> -x``), 2D joints
  ``u -> W - 1 - u``, boxes ``[x0, x1) -> [W - x1, W - x0)`` (exclusive ends);
- camera-frame MANO: axis-angle rotations mirrored (``R -> M R M``), ``transl`` mirrored, betas
  kept. That is exact when the left hand model's rest pose mirrors the right one's and the wrist
  sits at ``transl`` (the built-in skeleton; for real MANO ``transl`` is off by the difference of
  the two templates' root joints, a few millimetres);
- camera poses ``T_world_cam -> M T M`` (still rotations), intrinsics ``K -> F K M`` with
  ``F`` the column flip (``c_x -> W - 1 - c_x``, skew negated); FoVs unchanged.

``train.horizontal_flip`` is the probability per clip (0: off).
"""

from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.mano.mirror import mirror_points
from infinihand_ros.mano.mirror import POINT_MIRROR_SIGNS
from infinihand_ros.train import sequence_reader as keys
import torch

#: Keys whose side axis (2 of a batch (B, S, 2, ...)) is swapped and nothing else.
_SIDE_ONLY: Final = (keys.MASK_VALID, keys.HAND_PRESENT, keys.BOX_VALID, 'mano_betas')
#: Keys a mirror leaves as they are.
_UNCHANGED: Final = (keys.CAMERA_VALID, keys.FOV, keys.FRAME_INDEX, keys.SEQUENCE_INDEX)
#: Per-side 3D points mirrored through x = 0 (besides the side swap).
_POINTS: Final = (keys.JOINTS_CAM, keys.JOINTS_WORLD, 'mano_transl')
#: Per-side axis-angle rotations mirrored (besides the side swap).
_ROTATIONS: Final = ('mano_global_orient', 'mano_hand_pose')


def draw_flips(batch_size: int, probability: float, generator: torch.Generator) -> torch.Tensor:
    """Return (B,) bool: which clips of a batch are mirrored (one draw per clip)."""
    return torch.rand(batch_size, generator=generator) < probability


def _swap_sides(value: torch.Tensor) -> torch.Tensor:
    """Swap the [left, right] axis 2 of a (B, S, 2, ...) tensor."""
    return value.flip(2)


def _mirror_intrinsics(intrinsics: torch.Tensor, width: int) -> torch.Tensor:
    """Return ``F K M`` for (..., 3, 3) K: the camera of the column-flipped image."""
    column_flip = torch.tensor([[-1.0, 0.0, width - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                               dtype=intrinsics.dtype)
    mirror = torch.diag(torch.tensor(POINT_MIRROR_SIGNS, dtype=intrinsics.dtype))
    return column_flip @ intrinsics @ mirror


def _mirror_pose(T_world_cam: torch.Tensor) -> torch.Tensor:
    """Return ``M T M`` for (..., 4, 4) camera-to-world transforms (camera and world mirrored)."""
    mirror = torch.diag(torch.tensor((*POINT_MIRROR_SIGNS, 1.0), dtype=T_world_cam.dtype))
    return mirror @ T_world_cam @ mirror


def mirror_clip_batch(batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Return every clip of a batch (``sequence_reader`` keys, (B, S, ...)) mirrored.

    Raises:
        InputError: for a key this module does not know how to mirror (a new target must say
            how it mirrors rather than pass through unchanged).

    """
    width = batch[keys.IMAGES].shape[-1]
    out = {}
    for key, value in batch.items():
        if key in _UNCHANGED:
            out[key] = value
        elif key in (keys.IMAGES, keys.DEPTH):
            out[key] = value.flip(-1)
        elif key == keys.MASKS:
            out[key] = _swap_sides(value.flip(-1))
        elif key in _SIDE_ONLY:
            out[key] = _swap_sides(value)
        elif key in _POINTS:
            out[key] = _swap_sides(mirror_points(value))
        elif key in _ROTATIONS:
            out[key] = _swap_sides(mirror_axis_angle(value))
        elif key == keys.JOINTS_2D:
            u, v = _swap_sides(value).unbind(-1)
            out[key] = torch.stack((width - 1.0 - u, v), dim=-1)
        elif key == keys.BOXES:
            x0, y0, x1, y1 = _swap_sides(value).unbind(-1)
            out[key] = torch.stack((width - x1, y0, width - x0, y1), dim=-1)
        elif key == keys.INTRINSICS:
            out[key] = _mirror_intrinsics(value, width)
        elif key == keys.T_WORLD_CAM:
            out[key] = _mirror_pose(value)
        else:
            raise InputError(f'horizontal flip: no rule for batch key {key!r}; add one to '
                             'train/horizontal_flip.py')
    return out


def flip_clips(batch: dict[str, torch.Tensor], flips: torch.Tensor) -> dict[str, torch.Tensor]:
    """Return the batch with the clips where ``flips`` (B,) is True mirrored, others unchanged."""
    if not bool(flips.any()):
        return batch
    mirrored = mirror_clip_batch(batch)
    out = {}
    for key, value in batch.items():
        where = flips.reshape((-1,) + (1,) * (value.dim() - 1))
        out[key] = torch.where(where, mirrored[key], value)
    return out
