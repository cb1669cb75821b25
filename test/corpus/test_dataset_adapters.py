"""Adapters from the public layouts: each on a tiny fixture around a known hand."""

from pathlib import Path

from dataset_layouts import dexycb
from dataset_layouts import egodex
from dataset_layouts import fake_mano
from dataset_layouts import frames_rgb
from dataset_layouts import HEIGHT
from dataset_layouts import ho3d
from dataset_layouts import K
from dataset_layouts import random_poses
from dataset_layouts import WIDTH
from dataset_layouts import write_jpeg
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.corpus.adapters.arctic import read_arctic_sequence
from infinihand_ros.corpus.adapters.dexycb import iter_dexycb
from infinihand_ros.corpus.adapters.egodex import iter_egodex
from infinihand_ros.corpus.adapters.ho3d import iter_ho3d
from infinihand_ros.corpus.builder import build_corpus
from infinihand_ros.corpus.builder import BuildSettings
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.mano_layer import ManoHandModel
from infinihand_ros.synth.known_tracks import known_track
import numpy as np
import pytest
from safetensors.numpy import load_file
import torch

FRAMES = 3


def _track(side: int, seed: int = 3) -> np.ndarray:
    return known_track(np.random.default_rng(seed), side, FRAMES).joints


def test_dexycb_left_hand_lands_in_the_left_slot_at_its_pixels(tmp_path: Path) -> None:
    """A DexYCB 'left' sequence: joints in the left slot, unchanged, projecting where K says."""
    joints = _track(LEFT)
    sequence = next(iter_dexycb([dexycb(tmp_path, joints, 'left')]))
    assert sequence.hand_present.tolist() == [[True, False], [False, False], [True, False]]
    np.testing.assert_allclose(sequence.joints_cam[[0, 2], LEFT], joints[[0, 2]], atol=1e-6)
    np.testing.assert_allclose(project_points(sequence.joints_cam[0, LEFT], sequence.K[0]),
                               project_points(joints[0], K), atol=1e-4)
    assert sequence.image_size == (WIDTH, HEIGHT)
    assert sequence.read_rgb(2).shape == (HEIGHT, WIDTH, 3)
    np.testing.assert_array_equal(sequence.T_world_cam[1], np.eye(4))


def test_dexycb_sequence_builds_with_fitted_mano(tmp_path: Path) -> None:
    """Through the builder the fitted built-in hand reproduces the joints within 5 mm.

    (Three frames, one without a hand: the fit's priors weigh more than on long tracks.)
    """
    joints = _track(RIGHT)
    models = tuple(BuiltinHandModel(side, dtype=torch.float64) for side in (0, 1))
    manifest = build_corpus(iter_dexycb([dexycb(tmp_path / 'in', joints, 'right')]),
                            tmp_path / 'out', models, BuildSettings())
    assert manifest['sources'] == [{'source': 'dexycb', 'licence': 'CC BY-NC 4.0'}]
    arrays = load_file(str(tmp_path / 'out' / manifest['stage_2'][0] / 'annotations.safetensors'))
    assert np.nanmax(arrays['mano_fit_error_mm'][:, RIGHT]) < 5.0
    np.testing.assert_allclose(arrays['joints_cam'][0, RIGHT], joints[0], atol=1e-6)


def test_ho3d_opengl_joints_come_back_in_our_frame_and_order(tmp_path: Path) -> None:
    """The OpenGL, MANO-ordered HO-3D joints map to OpenCV OpenPose order; z is forward."""
    joints = _track(RIGHT)
    sequence = next(iter_ho3d([ho3d(tmp_path, joints)]))
    assert sequence.hand_present[:, RIGHT].tolist() == [True, True, False]
    assert not sequence.hand_present[:, LEFT].any()
    np.testing.assert_allclose(sequence.joints_cam[:2, RIGHT], joints[:2], atol=1e-9)
    assert np.all(sequence.joints_cam[:2, RIGHT, :, 2] > 0)
    np.testing.assert_allclose(sequence.K[0], K)


def test_egodex_arkit_camera_and_world_joints_land_in_the_camera(tmp_path: Path) -> None:
    """The ARKit poses and world joints give our camera-frame joints and a first-camera world."""
    joints = _track(RIGHT)
    poses = random_poses(np.random.default_rng(5), FRAMES)
    sequence = next(iter_egodex([egodex(tmp_path, joints, 'right', poses)]))
    np.testing.assert_allclose(sequence.joints_cam[:, RIGHT], joints, atol=1e-9)
    assert sequence.joint_valid[0, RIGHT].sum() == 20 and sequence.joint_valid[1:, RIGHT].all()
    assert not sequence.hand_present[:, LEFT].any()
    np.testing.assert_allclose(sequence.T_world_cam[0], np.eye(4), atol=1e-9)
    np.testing.assert_allclose(sequence.T_world_cam[2], np.linalg.inv(poses[0]) @ poses[2],
                               atol=1e-9)
    assert sequence.read_rgb(2).shape == (HEIGHT, WIDTH, 3)
    assert sequence.read_rgb(0).shape == (HEIGHT, WIDTH, 3)


def _arctic_root(root: Path, sides: dict, R: np.ndarray, t: np.ndarray) -> Path:
    raw = root / 'raw_seqs' / 's01'
    raw.mkdir(parents=True)
    np.save(raw / 'box_grab_01.mano.npy', sides, allow_pickle=True)
    np.save(raw / 'box_grab_01.egocam.dist.npy', {
        'R_k_cam_np': R, 'T_k_cam_np': t[..., None], 'intrinsics': K,
        'dist8': np.zeros(8)}, allow_pickle=True)
    (root / 'meta').mkdir()
    (root / 'meta' / 'misc.json').write_text('{"s01": {"ioi_offset": 10, "image_size": '
                                             f'[[{WIDTH}, {HEIGHT}]]}}}}')
    for index in range(FRAMES):
        write_jpeg(root / 'images' / 's01' / 'box_grab_01' / '0' / f'{index + 10:05d}.jpg',
                   frames_rgb(1, index)[0])
    return root


def test_arctic_flat_hand_wrist_lands_at_root_plus_translation(tmp_path: Path) -> None:
    """A flat ARCTIC hand (pose = -hands_mean) has its wrist at J0 + trans in the world."""
    rng = np.random.default_rng(11)
    mano = (fake_mano(rng, LEFT), fake_mano(rng, RIGHT))
    R = np.repeat(np.eye(3)[None], FRAMES, axis=0)
    t = np.array([[0.0, 0.0, 0.5]] * FRAMES)
    trans = rng.normal(scale=0.05, size=(FRAMES, 3))
    sides = {name: {'rot': np.zeros((FRAMES, 3)),
                    'pose': np.tile(-mano[side].hands_mean, (FRAMES, 1)),
                    'trans': trans, 'shape': np.zeros(10), 'fitting_err': np.zeros(FRAMES)}
             for side, name in enumerate(('left', 'right'))}
    sequence = read_arctic_sequence(_arctic_root(tmp_path, sides, R, t), 's01', 'box_grab_01',
                                    mano, keep_mano=True)
    for side in (LEFT, RIGHT):
        model = ManoHandModel(mano[side], dtype=torch.float64)
        root = model.rest_joints(torch.zeros(1, 10, dtype=torch.float64))[0, 0].numpy()
        np.testing.assert_allclose(sequence.joints_cam[:, side, 0], root + trans + t, atol=1e-9)
        np.testing.assert_allclose(sequence.mano_cam['hand_pose'][:, side], 0.0, atol=1e-12)
    assert sequence.image_size == (WIDTH, HEIGHT)
    assert sequence.read_rgb(1).shape == (HEIGHT, WIDTH, 3)


def test_arctic_camera_mano_poses_to_the_camera_joints(tmp_path: Path) -> None:
    """Moved into a rotated egocentric camera, the kept MANO gives the transformed joints."""
    rng = np.random.default_rng(12)
    mano = (fake_mano(rng, LEFT), fake_mano(rng, RIGHT))
    poses = random_poses(rng, FRAMES)
    sides = {name: {'rot': rng.normal(size=(FRAMES, 3)), 'pose': rng.normal(
        scale=0.3, size=(FRAMES, 45)), 'trans': rng.normal(size=(FRAMES, 3)),
        'shape': rng.normal(size=10), 'fitting_err': np.zeros(FRAMES)}
        for name in ('left', 'right')}
    sequence = read_arctic_sequence(
        _arctic_root(tmp_path, sides, poses[:, :3, :3], poses[:, :3, 3]), 's01', 'box_grab_01',
        mano, keep_mano=True)
    for side in (LEFT, RIGHT):
        model = ManoHandModel(mano[side], dtype=torch.float64)
        posed = model(*(torch.as_tensor(sequence.mano_cam[name][:, side]) for name in
                        ('global_orient', 'hand_pose', 'betas', 'transl'))).joints.numpy()
        np.testing.assert_allclose(posed, sequence.joints_cam[:, side], atol=1e-8)
    np.testing.assert_allclose(sequence.T_world_cam[0], np.eye(4), atol=1e-9)
    assert read_arctic_sequence(tmp_path, 's01', 'box_grab_01', mano, False).mano_cam is None


def test_dexycb_rejects_missing_intrinsics(tmp_path: Path) -> None:
    """A DexYCB root without its calibration is an InputError naming the file."""
    root = dexycb(tmp_path, _track(LEFT), 'left')
    next(root.glob('calibration/intrinsics/*.yml')).unlink()
    with pytest.raises(ValueError, match='no DexYCB colour intrinsics'):
        next(iter_dexycb([root]))
