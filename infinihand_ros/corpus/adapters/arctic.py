"""Adapter of ARCTIC (bimanual MANO in a mocap world, moving egocentric camera).

Layout and conventions, from ARCTIC's ``docs/data/data_doc.md`` and
``src/arctic/preprocess_dataset.py`` / ``processing.py`` (zc-alexfan/arctic)::

    ROOT/raw_seqs/<subject>/<seq>.mano.npy        {'right'|'left': rot (T, 3), pose (T, 45),
                                                   trans (T, 3), shape (10,), fitting_err (T,)}
    ROOT/raw_seqs/<subject>/<seq>.egocam.dist.npy R_k_cam_np (T, 3, 3), T_k_cam_np (T, 3, 1),
                                                   intrinsics (3, 3), dist8 (8,)
    ROOT/meta/misc.json                           <subject>: ioi_offset (image index of frame 0),
                                                   image_size (per view: width, height)
    ROOT/images/<subject>/<seq>/0/%05d.jpg        view 0: the egocentric camera (distorted)

MANO parameters are world-frame, for smplx's MANO layer with ``flat_hand_mean=False`` (poses
relative to the mean pose; ours are relative to the flat hand, so ``hands_mean`` is added).
``world2ego = [R_k_cam | T_k_cam]`` maps world points into the egocentric camera, an OpenCV
camera whose images carry the 8-coefficient OpenCV distortion ``dist8``; frames are undistorted
on load so the pinhole ``intrinsics`` hold. Joints need the real MANO model (the files are the
user's): the adapter poses it, then keeps its MANO in the camera frame when the corpus uses
real MANO too, else leaves MANO to be fitted to the joints. Captured at 30 Hz.
"""

from collections.abc import Iterator
import json
from pathlib import Path
from typing import Final

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.corpus.adapters.frames import ImageFiles
from infinihand_ros.corpus.adapters.frames import rebase_to_first
from infinihand_ros.corpus.adapters.frames import stamps_from_rate
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_layer import ManoHandModel
import numpy as np
import torch

SOURCE: Final = 'arctic'
LICENCE: Final = 'ARCTIC licence (non-commercial research)'
FPS: Final = 30.0
EGO_VIEW: Final = 0
_FIELDS: Final = ('global_orient', 'hand_pose', 'betas', 'transl')


def _load_dict(path: Path) -> dict:
    try:
        return np.load(path, allow_pickle=True).item()
    except (OSError, ValueError) as exc:
        raise InputError(f'{path}: unreadable ARCTIC file ({exc})') from exc


def _world_hand(params: dict, data: ManoData, frames: int) -> dict[str, np.ndarray]:
    """One hand's world MANO arrays in our convention (flat-hand relative)."""
    pose = np.asarray(params['pose'], np.float64).reshape(frames, 15, 3)
    return {'global_orient': np.asarray(params['rot'], np.float64).reshape(frames, 3),
            'hand_pose': pose + data.hands_mean.reshape(15, 3),
            'betas': np.broadcast_to(np.asarray(params['shape'], np.float64).reshape(-1, 10),
                                     (frames, 10)).copy(),
            'transl': np.asarray(params['trans'], np.float64).reshape(frames, 3)}


def _to_camera(world: dict[str, np.ndarray], model: ManoHandModel, R_cam_world: np.ndarray,
               t_cam_world: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Camera-frame joints (T, 21, 3) and MANO arrays of one hand."""
    tensors = [torch.as_tensor(world[name], dtype=torch.float64) for name in _FIELDS]
    with torch.no_grad():
        joints_world = model(*tensors).joints.numpy()
        roots = model.rest_joints(tensors[2])[:, 0].numpy()
    joints = np.einsum('tij,tnj->tni', R_cam_world, joints_world) + t_cam_world[:, None]
    cam = {name: world[name].copy() for name in _FIELDS}
    for index in range(len(joints)):
        moved = transform_mano_params(ManoParams(*(world[n][index] for n in _FIELDS)),
                                      R_cam_world[index], t_cam_world[index], roots[index])
        cam['global_orient'][index], cam['transl'][index] = moved.global_orient, moved.transl
    return joints, cam


def read_arctic_sequence(root: Path, subject: str, name: str, mano: tuple[ManoData, ManoData],
                         keep_mano: bool) -> CorpusSequence:
    """Read one ARCTIC sequence's egocentric view.

    Args:
        root: the ``arctic_data/data`` folder.
        subject: e.g. 's01'.
        name: sequence name, e.g. 'box_grab_01'.
        mano: real MANO arrays (left, right) the dataset's parameters belong to.
        keep_mano: keep the dataset's MANO (the corpus's hand model is this real MANO), else
            leave it to be fitted.

    """
    raw = root / 'raw_seqs' / subject
    hands = _load_dict(raw / f'{name}.mano.npy')
    ego = _load_dict(raw / f'{name}.egocam.dist.npy')
    misc = json.loads((root / 'meta' / 'misc.json').read_text(encoding='utf-8'))[subject]
    offset = int(misc['ioi_offset'])
    width, height = (int(v) for v in misc['image_size'][EGO_VIEW])
    R = np.asarray(ego['R_k_cam_np'], np.float64)
    frames = len(R)
    t = np.asarray(ego['T_k_cam_np'], np.float64).reshape(frames, 3)
    K = np.asarray(ego['intrinsics'], np.float64)
    joints = np.zeros((frames, len(SIDES), 21, 3))
    mano_cam = {name: np.zeros((frames, len(SIDES), *shape)) for name, shape in
                zip(_FIELDS, ((3,), (15, 3), (10,), (3,)))}
    for side in SIDES:
        model = ManoHandModel(mano[side], dtype=torch.float64)
        world = _world_hand(hands[SIDE_NAMES[side]], mano[side], frames)
        joints[:, side], cam = _to_camera(world, model, R, t)
        for field in _FIELDS:
            mano_cam[field][:, side] = cam[field]
    images = [root / 'images' / subject / name / str(EGO_VIEW) / f'{i + offset:05d}.jpg'
              for i in range(frames)]
    T_world_cam = geometry.invert_transform(geometry.make_transform(R, t))
    return CorpusSequence(
        sequence_id=f'{subject}.{name}', source=SOURCE, licence=LICENCE,
        image_size=(width, height),
        timestamp_ns=stamps_from_rate(frames, FPS), K=np.repeat(K[None], frames, axis=0),
        T_world_cam=rebase_to_first(T_world_cam),
        hand_present=np.ones((frames, len(SIDES)), bool), joints_cam=joints,
        joint_valid=np.ones((frames, len(SIDES), 21), bool),
        mano_cam=mano_cam if keep_mano else None,
        read_rgb=ImageFiles(images, K, np.asarray(ego['dist8'], np.float64)))


def iter_arctic(roots: list[Path], mano: tuple[ManoData, ManoData],
                keep_mano: bool) -> Iterator[CorpusSequence]:
    """Yield every sequence of ``raw_seqs`` under each root (``arctic_data/data``), sorted."""
    for root in map(Path, roots):
        for path in sorted((root / 'raw_seqs').glob('*/*.mano.npy')):
            yield read_arctic_sequence(root, path.parent.name,
                                       path.name[:-len('.mano.npy')], mano, keep_mano)
