"""Adapter of EgoDex (Apple Vision Pro recordings: HDF5 joint transforms + mp4 video).

Layout and conventions, from the EgoDex README (ml-site.cdn-apple.com/datasets/egodex) as
read by public loaders (IstariRobotics/egohub ``adapters/egodex``)::

    ROOT/<part>/<task>/<n>.hdf5   camera/intrinsic (3, 3); transforms/<name> (T, 4, 4)
                                  world-from-joint or world-from-camera; confidences/<name> (T,)
    ROOT/<part>/<task>/<n>.mp4    the matching 1080p 30 Hz video

The world and the camera follow ARKit: right-handed, y up, and the camera looks along its -z
(x right, y up, z toward the user), so our camera pose is ``transforms/camera @ GL_TO_CV``,
re-based to the first frame. Joint names are ``left``/``right`` + ``Hand`` (the wrist),
``ThumbKnuckle``, ``ThumbIntermediateBase``, ``ThumbIntermediateTip``, ``ThumbTip`` and, per
finger (Index, Middle, Ring, Little), ``<F>FingerKnuckle`` (MCP), ``IntermediateBase`` (PIP),
``IntermediateTip`` (DIP) and ``Tip``; the ``Metacarpal`` joints have no counterpart in our 21.
A joint counts as annotated where its confidence reaches ``MIN_CONFIDENCE``.
"""

from collections.abc import Iterator
from pathlib import Path
from typing import Final

import h5py
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.corpus.adapters.frames import empty_hands
from infinihand_ros.corpus.adapters.frames import GL_TO_CV
from infinihand_ros.corpus.adapters.frames import image_size_of
from infinihand_ros.corpus.adapters.frames import rebase_to_first
from infinihand_ros.corpus.adapters.frames import stamps_from_rate
from infinihand_ros.corpus.adapters.frames import VideoFrames
from infinihand_ros.corpus.sequence import CorpusSequence
import numpy as np

SOURCE: Final = 'egodex'
LICENCE: Final = 'CC BY-NC-ND 4.0'
FPS: Final = 30.0
#: ARKit's tracking confidence is in [0, 1]; below this a joint is treated as not annotated.
MIN_CONFIDENCE: Final = 0.5
_FINGERS: Final = ('IndexFinger', 'MiddleFinger', 'RingFinger', 'LittleFinger')
#: EgoDex joint-name suffixes in our 21-joint OpenPose order.
JOINT_SUFFIXES: Final = (
    ('Hand', 'ThumbKnuckle', 'ThumbIntermediateBase', 'ThumbIntermediateTip', 'ThumbTip')
    + tuple(f'{finger}{part}' for finger in _FINGERS
            for part in ('Knuckle', 'IntermediateBase', 'IntermediateTip', 'Tip')))
_CV_POSE: Final = np.diag([*np.diag(GL_TO_CV), 1.0])


def read_egodex_episode(hdf5_path: Path) -> CorpusSequence:
    """Read one EgoDex episode (the hdf5 file; the mp4 beside it)."""
    video = hdf5_path.with_suffix('.mp4')
    if not video.is_file():
        raise InputError(f'{hdf5_path}: no video {video.name} beside it')
    with h5py.File(hdf5_path, 'r') as data:
        K = np.asarray(data['camera/intrinsic'], np.float64)
        T_world_arkit = np.asarray(data['transforms/camera'], np.float64)
        frames = len(T_world_arkit)
        T_world_cam = T_world_arkit @ _CV_POSE
        T_cam_world = np.linalg.inv(T_world_cam)
        present, joints, valid = empty_hands(frames)
        for side, name in enumerate(SIDE_NAMES):
            for joint, suffix in enumerate(JOINT_SUFFIXES):
                key = f'{name}{suffix}'
                if f'transforms/{key}' not in data:
                    continue
                world = np.asarray(data[f'transforms/{key}'], np.float64)[:, :3, 3]
                joints[:, side, joint] = np.einsum('tij,tj->ti', T_cam_world[:, :3, :3],
                                                   world) + T_cam_world[:, :3, 3]
                confidence = np.asarray(data[f'confidences/{key}'], np.float64) \
                    if f'confidences/{key}' in data else np.ones(frames)
                valid[:, side, joint] = confidence >= MIN_CONFIDENCE
            present[:, side] = valid[:, side].any(axis=1)
    read_rgb = VideoFrames(video)
    return CorpusSequence(
        sequence_id=f'{hdf5_path.parent.name}.{hdf5_path.stem}', source=SOURCE,
        licence=LICENCE, image_size=image_size_of(read_rgb),
        timestamp_ns=stamps_from_rate(frames, FPS), K=np.repeat(K[None], frames, axis=0),
        T_world_cam=rebase_to_first(T_world_cam), hand_present=present, joints_cam=joints,
        joint_valid=valid, mano_cam=None, read_rgb=read_rgb)


def iter_egodex(roots: list[Path]) -> Iterator[CorpusSequence]:
    """Yield every episode (``*.hdf5`` with its ``.mp4``) under each root, sorted."""
    for root in map(Path, roots):
        for path in sorted(root.glob('**/*.hdf5')):
            yield read_egodex_episode(path)
