"""Builders of tiny datasets in the public layouts, around known built-in hands.

Each builder writes a few frames of one dataset's layout from a known camera-frame hand track
(``data/synthetic_tracks.py``) so an adapter test can check the hand lands where it should.
"""

from pathlib import Path
import pickle

import av
import cv2
import h5py
from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.core.hand_conventions import OPENPOSE_TO_MANO
from infinihand_ros.data.adapters.egodex import JOINT_SUFFIXES
from infinihand_ros.data.adapters.frames import GL_TO_CV
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_file import NUM_FACES
from infinihand_ros.mano.mano_file import NUM_POSE_FEATURES
from infinihand_ros.mano.mano_file import NUM_POSE_PARAMS
from infinihand_ros.mano.mano_file import NUM_VERTICES
import numpy as np
import yaml

WIDTH, HEIGHT = 64, 48
K = np.array([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])


def frames_rgb(count: int, seed: int = 0) -> list[np.ndarray]:
    """Return ``count`` random (HEIGHT, WIDTH, 3) uint8 RGB frames."""
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8) for _ in range(count)]


def write_jpeg(path: Path, rgb: np.ndarray) -> None:
    """Write an RGB frame as JPEG (folders created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.ascontiguousarray(rgb[:, :, ::-1]))


def write_mp4(path: Path, frames: list[np.ndarray], fps: int = 30) -> None:
    """Encode RGB frames as H.264 mp4."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), 'w') as container:
        stream = container.add_stream('libx264', rate=fps)
        stream.width, stream.height, stream.pix_fmt = WIDTH, HEIGHT, 'yuv420p'
        for rgb in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(rgb, format='rgb24')):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)


def random_poses(rng: np.random.Generator, frames: int) -> np.ndarray:
    """Return (T, 4, 4) random rigid camera-to-world poses."""
    poses = np.repeat(np.eye(4)[None], frames, axis=0)
    for index in range(frames):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        poses[index, :3, :3] = q * np.sign(np.linalg.det(q))
        poses[index, :3, 3] = rng.normal(size=3)
    return poses


def dexycb(root: Path, joints: np.ndarray, side: str) -> Path:
    """One sequence, one camera; ``joints`` (T, 21, 3) camera frame; frame 1 has no hand."""
    serial = '836212060125'
    calib = root / 'calibration' / 'intrinsics' / f'{serial}_640x480.yml'
    calib.parent.mkdir(parents=True)
    calib.write_text(yaml.safe_dump({'color': {'fx': float(K[0, 0]), 'fy': float(K[1, 1]),
                                               'ppx': float(K[0, 2]), 'ppy': float(K[1, 2])}}))
    sequence = root / '20200709-subject-01' / '20200709_141754'
    view = sequence / serial
    view.mkdir(parents=True)
    (sequence / 'meta.yml').write_text(yaml.safe_dump(
        {'num_frames': len(joints), 'mano_sides': [side], 'serials': [serial]}))
    for index, (points, rgb) in enumerate(zip(joints, frames_rgb(len(joints)))):
        label = np.full((1, 21, 3), -1.0, np.float32) if index == 1 else points[None]
        np.savez(view / f'labels_{index:06d}.npz', joint_3d=label.astype(np.float32),
                 pose_m=np.zeros((1, 51), np.float32))
        write_jpeg(view / f'color_{index:06d}.jpg', rgb)
    return root


def ho3d(root: Path, joints: np.ndarray) -> Path:
    """One right-hand sequence in an OpenGL camera; the last frame is an evaluation frame."""
    sequence = root / 'train' / 'ABF10'
    (sequence / 'meta').mkdir(parents=True)
    for index, (points, rgb) in enumerate(zip(joints, frames_rgb(len(joints)))):
        hand = (points @ GL_TO_CV)[list(OPENPOSE_TO_MANO)]
        if index == len(joints) - 1:
            hand = hand[0]
        meta = {'camMat': K, 'handJoints3D': hand, 'handPose': np.zeros(48),
                'handBeta': np.zeros(10), 'handTrans': hand.reshape(-1, 3)[0]}
        with (sequence / 'meta' / f'{index:04d}.pkl').open('wb') as handle:
            pickle.dump(meta, handle)
        write_jpeg(sequence / 'rgb' / f'{index:04d}.jpg', rgb)
    return root


def fake_mano(rng: np.random.Generator, side: int) -> ManoData:
    """Random but well-formed MANO arrays (not the real model)."""
    regressor = np.zeros((NUM_MANO_JOINTS, NUM_VERTICES))
    for joint in range(NUM_MANO_JOINTS):
        regressor[joint, rng.choice(NUM_VERTICES, 8, replace=False)] = 1.0 / 8
    return ManoData(
        v_template=rng.normal(scale=0.04, size=(NUM_VERTICES, 3)),
        shapedirs=rng.normal(scale=0.002, size=(NUM_VERTICES, 3, 10)),
        posedirs=rng.normal(scale=0.002, size=(NUM_VERTICES, 3, NUM_POSE_FEATURES)),
        joint_regressor=regressor,
        weights=rng.dirichlet(np.ones(NUM_MANO_JOINTS), size=NUM_VERTICES),
        kintree_table=np.array([MANO_PARENTS, range(NUM_MANO_JOINTS)]),
        faces=rng.integers(0, NUM_VERTICES, (NUM_FACES, 3)),
        hands_components=rng.normal(size=(NUM_POSE_PARAMS, NUM_POSE_PARAMS)),
        hands_mean=rng.normal(scale=0.2, size=NUM_POSE_PARAMS), side=side)


def egodex(root: Path, joints: np.ndarray, side: str, T_world_cam: np.ndarray) -> Path:
    """One EgoDex episode: ARKit camera poses, world joint transforms, confidences, mp4."""
    path = root / 'part1' / 'basic_pick_place' / '0.hdf5'
    path.parent.mkdir(parents=True)
    arkit = T_world_cam @ np.diag([1.0, -1.0, -1.0, 1.0])
    world = np.einsum('tij,tnj->tni', T_world_cam[:, :3, :3], joints) + T_world_cam[:, None, :3, 3]
    with h5py.File(path, 'w') as data:
        data['camera/intrinsic'] = K
        data['transforms/camera'] = arkit
        for joint, suffix in enumerate(JOINT_SUFFIXES):
            transform = np.repeat(np.eye(4)[None], len(joints), axis=0)
            transform[:, :3, 3] = world[:, joint]
            data[f'transforms/{side}{suffix}'] = transform
            confidence = np.ones(len(joints))
            confidence[0] = 0.1 if joint == 8 else 1.0
            data[f'confidences/{side}{suffix}'] = confidence
        data['transforms/leftIndexFingerMetacarpal'] = np.repeat(np.eye(4)[None], len(joints), 0)
    write_mp4(path.with_suffix('.mp4'), frames_rgb(len(joints)))
    return root
