"""Builders of tiny datasets in the public layouts, around known built-in hands.

Each builder writes a few frames of one dataset's layout from a known camera-frame hand track
(``synth/known_tracks.py``) so an adapter test can check the hand lands where it should.
"""

import dataclasses
import io
import json
from pathlib import Path
import pickle
import tarfile

import av
import cv2
import h5py
from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.core.hand_conventions import OPENPOSE_TO_MANO
from infinihand_ros.corpus.adapters.egodex import JOINT_SUFFIXES
from infinihand_ros.corpus.adapters.frames import GL_TO_CV
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_file import NUM_FACES
from infinihand_ros.mano.mano_file import NUM_POSE_FEATURES
from infinihand_ros.mano.mano_file import NUM_POSE_PARAMS
from infinihand_ros.mano.mano_file import NUM_VERTICES
import numpy as np
from scipy.spatial.transform import Rotation
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


#: HOT3D fixture camera: FISHEYE624 (fx, fy, cx, cy, 6 radial, 2 tangential, 4 thin prism), one
#: radial term only, so the fixture can place pixels with the closed form below.
HOT3D_SIZE = 160
HOT3D_K1 = 0.05
HOT3D_PARAMS = [60.0, 60.0, 79.5, 79.5, HOT3D_K1] + [0.0] * 11
#: PCA coefficients that give the flat hand with ``hot3d_mano``'s mean pose.
HOT3D_FLAT_THETAS = np.linspace(-1.0, 1.0, 15)


def hot3d_mano(rng: np.random.Generator, side: int) -> ManoData:
    """Fake MANO arrays whose mean pose is cancelled by ``HOT3D_FLAT_THETAS``."""
    data = fake_mano(rng, side)
    mean = -(HOT3D_FLAT_THETAS @ data.hands_components[:15])
    return dataclasses.replace(data, hands_mean=mean)


def hot3d_fisheye_pixel(point_cam: np.ndarray) -> np.ndarray:
    """Pixel of a camera-frame point in the fixture's fisheye: c + f theta (1 + k1 theta^2)."""
    x, y, z = point_cam
    r = np.hypot(x, y)
    theta = np.arctan2(r, z)
    fx, fy, cx, cy = HOT3D_PARAMS[:4]
    scale = theta * (1.0 + HOT3D_K1 * theta ** 2) / r
    return np.array([cx + fx * x * scale, cy + fy * y * scale])


def hot3d_hand(thetas: np.ndarray | None, wrist_xform: np.ndarray) -> dict:
    """One side of ``hands.json``; ``thetas`` None leaves only the UmeTrack pose (MANO failed)."""
    hand = {'umetrack_pose': {'joint_angles': [0.0] * 20, 'T_world_from_wrist': {
        'quaternion_wxyz': [1.0, 0.0, 0.0, 0.0], 'translation_xyz': [0.0, 0.0, 0.0]}},
        'boxes_amodal': {}, 'visibilities_modeled': {}}
    if thetas is not None:
        hand['mano_pose'] = {'thetas': [float(v) for v in thetas],
                             'wrist_xform': [float(v) for v in wrist_xform]}
    return hand


def _se3_json(pose: np.ndarray) -> dict:
    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    return {'quaternion_wxyz': [float(w), float(x), float(y), float(z)],
            'translation_xyz': [float(v) for v in pose[:3, 3]]}


def hot3d_clip(root: Path, T_world_cam: np.ndarray, hands: list[dict | None],
               betas: np.ndarray, dots_cam: np.ndarray | None = None, stream: str = '214-1',
               as_tar: bool = True) -> Path:
    """One HOT3D clip (``clip-000001.tar`` under ``root/train_aria``, or a folder).

    ``hands`` is each frame's ``hands.json`` (None: no file); ``dots_cam`` (T, 3) camera-frame
    points drawn as bright blobs where the fisheye sees them. Returns the clip's path.
    """
    members: dict[str, bytes] = {}
    grid = np.stack(np.meshgrid(np.arange(HOT3D_SIZE), np.arange(HOT3D_SIZE)), axis=-1)
    for index, pose in enumerate(T_world_cam):
        key = f'{index:06d}'
        calibration = {'label': 'camera-rgb', 'stream_id': stream, 'serial_number': '0',
                       'image_width': HOT3D_SIZE, 'image_height': HOT3D_SIZE,
                       'projection_model_type': 'CameraModelType.FISHEYE624',
                       'projection_params': HOT3D_PARAMS,
                       'T_device_from_camera': _se3_json(np.eye(4)), 'max_solid_angle': 1.5}
        members[f'{key}.cameras.json'] = json.dumps(
            {stream: {'calibration': calibration, 'T_world_from_camera': _se3_json(pose)}})
        members[f'{key}.info.json'] = json.dumps(
            {'device': 'Aria', 'image_timestamps_ns': {stream: 10**9 + index * 33_333_333}})
        if hands[index] is not None:
            members[f'{key}.hands.json'] = json.dumps(hands[index])
        image = np.zeros((HOT3D_SIZE, HOT3D_SIZE), np.float64)
        if dots_cam is not None:
            spot = hot3d_fisheye_pixel(dots_cam[index])
            image = 255.0 * np.exp(-((grid - spot) ** 2).sum(-1) / (2 * 1.5 ** 2))
        gray = image.astype(np.uint8)
        pixels = np.repeat(gray[..., None], 3, axis=-1) if stream == '214-1' else gray
        _, jpeg = cv2.imencode('.jpg', pixels, [cv2.IMWRITE_JPEG_QUALITY, 98])
        members[f'{key}.image_{stream}.jpg'] = jpeg.tobytes()
    members['__hand_shapes.json__'] = json.dumps(
        {'mano': [float(v) for v in betas], 'umetrack': {}})
    folder = root / 'train_aria'
    folder.mkdir(parents=True, exist_ok=True)
    if not as_tar:
        clip = folder / 'clip-000001'
        clip.mkdir()
        for name, data in members.items():
            (clip / name).write_bytes(data.encode() if isinstance(data, str) else data)
        return clip
    clip = folder / 'clip-000001.tar'
    with tarfile.open(clip, 'w') as tar:
        for name, data in members.items():
            raw = data.encode() if isinstance(data, str) else data
            info = tarfile.TarInfo(name)
            info.size = len(raw)
            tar.addfile(info, io.BytesIO(raw))
    return clip
