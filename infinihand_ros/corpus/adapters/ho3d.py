"""Adapter of HO-3D (v2 / v3): one right hand with an object, fixed camera per sequence.

Layout and conventions, from the HO-3D README (shreyashampali/ho3d) and its visualisation
scripts::

    ROOT/<split>/<sequence>/rgb/%04d.jpg (v3) or .png (v2)
    ROOT/<split>/<sequence>/meta/%04d.pkl   dict: camMat (3, 3), handJoints3D (21, 3), ...

``handJoints3D`` is in an OpenGL camera frame (y up, z toward the viewer; the README's
``coordChangeMat = diag(1, -1, -1)``), in MANO's joint order with the five tips appended, so
ours is ``handJoints3D[MANO_TO_OPENPOSE] @ GL_TO_CV``. Only right hands are annotated.
Evaluation frames whose ``handJoints3D`` is a single root point or missing count as no hand.
The camera is static (identity trajectory, Stage II); MANO is fitted to the joints, since
``handPose`` belongs to real MANO. HO-3D publishes no frame rate; stamps assume 30 Hz.
"""

from collections.abc import Iterator
from pathlib import Path
import pickle
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import MANO_TO_OPENPOSE
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.corpus.adapters.frames import empty_hands
from infinihand_ros.corpus.adapters.frames import GL_TO_CV
from infinihand_ros.corpus.adapters.frames import image_size_of
from infinihand_ros.corpus.adapters.frames import ImageFiles
from infinihand_ros.corpus.adapters.frames import stamps_from_rate
from infinihand_ros.corpus.sequence import CorpusSequence
import numpy as np

SOURCE: Final = 'ho3d'
LICENCE: Final = 'HO-3D terms of use (research only)'
FPS: Final = 30.0
IMAGE_SUFFIXES: Final = ('.jpg', '.png')


def _read_meta(path: Path) -> dict:
    try:
        with path.open('rb') as handle:
            meta = pickle.load(handle, encoding='latin1')
    except (OSError, pickle.UnpicklingError, EOFError) as exc:
        raise InputError(f'{path}: unreadable HO-3D meta file ({exc})') from exc
    if not isinstance(meta, dict) or meta.get('camMat') is None:
        raise InputError(f'{path}: expected a dict with camMat')
    return meta


def read_ho3d_sequence(sequence_dir: Path) -> CorpusSequence:
    """Read one HO-3D sequence folder."""
    metas = sorted((sequence_dir / 'meta').glob('*.pkl'))
    if not metas:
        raise InputError(f'{sequence_dir}: no meta/*.pkl files')
    frames = len(metas)
    present, joints, valid = empty_hands(frames)
    K = np.zeros((frames, 3, 3))
    images = []
    for index, path in enumerate(metas):
        meta = _read_meta(path)
        K[index] = np.asarray(meta['camMat'], np.float64)
        points = meta.get('handJoints3D')
        if points is not None and np.shape(points) == (NUM_JOINTS, 3):
            joints[index, RIGHT] = np.asarray(points, np.float64)[list(MANO_TO_OPENPOSE)] \
                @ GL_TO_CV
            present[index, RIGHT] = valid[index, RIGHT] = True
        candidates = [sequence_dir / 'rgb' / (path.stem + s) for s in IMAGE_SUFFIXES]
        images.append(next((c for c in candidates if c.is_file()), candidates[0]))
    read_rgb = ImageFiles(images)
    return CorpusSequence(
        sequence_id=f'{sequence_dir.parent.name}.{sequence_dir.name}', source=SOURCE,
        licence=LICENCE, image_size=image_size_of(read_rgb),
        timestamp_ns=stamps_from_rate(frames, FPS), K=K,
        T_world_cam=np.repeat(np.eye(4)[None], frames, axis=0), hand_present=present,
        joints_cam=joints, joint_valid=valid, mano_cam=None, read_rgb=read_rgb)


def iter_ho3d(roots: list[Path]) -> Iterator[CorpusSequence]:
    """Yield every sequence (a folder with ``meta/``) under each root, sorted."""
    for root in map(Path, roots):
        for meta_dir in sorted(root.glob('**/meta')):
            if meta_dir.is_dir() and (meta_dir.parent / 'rgb').is_dir():
                yield read_ho3d_sequence(meta_dir.parent)
