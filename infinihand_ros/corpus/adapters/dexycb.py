"""Adapter of DexYCB (fixed RealSense cameras; one hand per sequence, MANO and 3D joints).

Layout and conventions, from the DexYCB README and ``dex_ycb_toolkit/dex_ycb.py``
(NVlabs/dex-ycb-toolkit)::

    ROOT/calibration/intrinsics/<serial>_640x480.yml   color: fx, fy, ppx, ppy
    ROOT/<subject>/<sequence>/meta.yml                  num_frames, mano_sides ['right'|'left']
    ROOT/<subject>/<sequence>/<serial>/color_%06d.jpg
    ROOT/<subject>/<sequence>/<serial>/labels_%06d.npz  joint_3d (1, 21, 3), -1 without a hand

``joint_3d`` is in the camera frame of that serial (OpenCV optical, metres) in the toolkit's
``_MANO_JOINTS`` order (wrist, then thumb, index, middle, ring, little from base to tip), which
is our OpenPose order. The side is ``mano_sides[0]``. Each (sequence, camera) pair becomes one
corpus sequence; the camera does not move, so its trajectory is the identity (Stage II). The
MANO ``pose_m`` is PCA coefficients of real MANO with the mean pose, a different model from the
built-in hand, so MANO is fitted to the joints instead. Captured at 30 Hz (DexYCB paper).
"""

from collections.abc import Iterator
from pathlib import Path
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import side_from_name
from infinihand_ros.corpus.adapters.frames import empty_hands
from infinihand_ros.corpus.adapters.frames import image_size_of
from infinihand_ros.corpus.adapters.frames import ImageFiles
from infinihand_ros.corpus.adapters.frames import stamps_from_rate
from infinihand_ros.corpus.sequence import CorpusSequence
import numpy as np
import yaml

SOURCE: Final = 'dexycb'
LICENCE: Final = 'CC BY-NC 4.0'
FPS: Final = 30.0
INTRINSICS_FILE: Final = 'calibration/intrinsics/{serial}_640x480.yml'
COLOR_FILE: Final = 'color_{index:06d}.jpg'
LABEL_FILE: Final = 'labels_{index:06d}.npz'


def _intrinsics(root: Path, serial: str) -> np.ndarray:
    path = root / INTRINSICS_FILE.format(serial=serial)
    try:
        color = yaml.safe_load(path.read_text(encoding='utf-8'))['color']
    except (OSError, KeyError, TypeError, yaml.YAMLError) as exc:
        raise InputError(f'{path}: no DexYCB colour intrinsics ({exc})') from exc
    return np.array([[color['fx'], 0.0, color['ppx']], [0.0, color['fy'], color['ppy']],
                     [0.0, 0.0, 1.0]])


def read_dexycb_view(root: Path, sequence_dir: Path, serial: str) -> CorpusSequence:
    """Read one camera view of a DexYCB sequence."""
    meta = yaml.safe_load((sequence_dir / 'meta.yml').read_text(encoding='utf-8'))
    frames, side = int(meta['num_frames']), side_from_name(meta['mano_sides'][0])
    view = sequence_dir / serial
    present, joints, valid = empty_hands(frames)
    for index in range(frames):
        with np.load(view / LABEL_FILE.format(index=index)) as labels:
            points = np.asarray(labels['joint_3d'], np.float64).reshape(-1, 3)
        if np.all(points == -1):
            continue
        present[index, side] = True
        joints[index, side] = points
        valid[index, side] = True
    read_rgb = ImageFiles([view / COLOR_FILE.format(index=i) for i in range(frames)])
    return CorpusSequence(
        sequence_id=f'{sequence_dir.parent.name}.{sequence_dir.name}.{serial}', source=SOURCE,
        licence=LICENCE, image_size=image_size_of(read_rgb),
        timestamp_ns=stamps_from_rate(frames, FPS),
        K=np.repeat(_intrinsics(root, serial)[None], frames, axis=0),
        T_world_cam=np.repeat(np.eye(4)[None], frames, axis=0), hand_present=present,
        joints_cam=joints, joint_valid=valid, mano_cam=None, read_rgb=read_rgb)


def iter_dexycb(roots: list[Path]) -> Iterator[CorpusSequence]:
    """Yield every (sequence, camera) view under each DexYCB root, sorted."""
    for root in map(Path, roots):
        for meta in sorted(root.glob('*/*/meta.yml')):
            for view in sorted(p for p in meta.parent.iterdir() if p.is_dir()):
                yield read_dexycb_view(root, meta.parent, view.name)
