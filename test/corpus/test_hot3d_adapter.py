"""The HOT3D-Clips adapter on tiny clips built in the published layout around known hands."""

from pathlib import Path

from dataset_layouts import hot3d_clip
from dataset_layouts import hot3d_fisheye_pixel
from dataset_layouts import HOT3D_FLAT_THETAS
from dataset_layouts import hot3d_hand
from dataset_layouts import hot3d_mano
from dataset_layouts import HOT3D_SIZE
from dataset_layouts import random_poses
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.geometry import transform_points
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.corpus.adapters.hot3d import iter_hot3d
from infinihand_ros.corpus.adapters.hot3d import read_hot3d_clip
from infinihand_ros.corpus.adapters.registry import AdapterContext
from infinihand_ros.corpus.adapters.registry import ADAPTERS
from infinihand_ros.corpus.builder import build_corpus
from infinihand_ros.corpus.builder import BuildSettings
from infinihand_ros.mano.mano_layer import ManoHandModel
import numpy as np
import pytest
import torch

FRAMES = 4
#: Camera-frame wrist of the flat right hand per frame: well off-axis, where fisheye and pinhole
#: pixels differ by several pixels.
WRIST_CAM = np.array([[0.24, -0.12, 0.30], [0.20, 0.10, 0.35], [0.05, 0.02, 0.4],
                      [-0.18, 0.15, 0.30]])


def _rest_root(mano: object, betas: np.ndarray) -> np.ndarray:
    model = ManoHandModel(mano, dtype=torch.float64)
    return model.rest_joints(torch.as_tensor(betas[None]))[0, 0].numpy()


def _flat_right_clip(root: Path, **kwargs: object) -> tuple[Path, tuple, np.ndarray]:
    """Frames 0 and 3 have a flat right hand; 1 has no right key; 2 only a UmeTrack pose."""
    rng = np.random.default_rng(21)
    mano = (hot3d_mano(rng, LEFT), hot3d_mano(rng, RIGHT))
    betas = rng.normal(scale=0.5, size=10)
    poses = random_poses(rng, FRAMES)
    wrist_world = transform_points(poses, WRIST_CAM[:, None])[:, 0]
    transl = wrist_world - _rest_root(mano[RIGHT], betas)
    hands = []
    for index in range(FRAMES):
        xform = np.concatenate([np.zeros(3), transl[index]])
        thetas = None if index == 2 else HOT3D_FLAT_THETAS
        hands.append({} if index == 1 else {'right': hot3d_hand(thetas, xform)})
    clip = hot3d_clip(root, poses, hands, betas, dots_cam=WRIST_CAM, **kwargs)
    return clip, mano, poses


def _blob_centre(rgb: np.ndarray) -> np.ndarray:
    weights = np.where(rgb[..., 0] > 60, rgb[..., 0].astype(np.float64), 0.0)
    v, u = np.indices(weights.shape)
    return np.array([(u * weights).sum(), (v * weights).sum()]) / weights.sum()


def test_hot3d_flat_hand_lands_at_its_camera_point_and_undistorted_pixel(tmp_path: Path) -> None:
    """The flat MANO hand's wrist is its camera point; the warped frame shows it where K says."""
    clip, mano, _ = _flat_right_clip(tmp_path)
    sequence = read_hot3d_clip(clip, mano, keep_mano=True)
    assert sequence.hand_present.tolist() == [[False, True], [False, False], [False, False],
                                              [False, True]]
    assert not sequence.joint_valid[[1, 2]].any() and sequence.joint_valid[[0, 3], RIGHT].all()
    assert np.isnan(sequence.joints_cam[1, RIGHT]).all()
    np.testing.assert_allclose(sequence.joints_cam[[0, 3], RIGHT, 0], WRIST_CAM[[0, 3]],
                               atol=1e-9)
    np.testing.assert_allclose(sequence.mano_cam['hand_pose'][[0, 3], RIGHT], 0.0, atol=1e-9)
    np.testing.assert_allclose(sequence.K[2], [[60.0, 0.0, 79.5], [0.0, 60.0, 79.5],
                                               [0.0, 0.0, 1.0]])
    assert sequence.image_size == (HOT3D_SIZE, HOT3D_SIZE)
    for index in (0, 3):
        expected = project_points(sequence.joints_cam[index, RIGHT, :1], sequence.K[index])[0]
        assert np.linalg.norm(expected - hot3d_fisheye_pixel(WRIST_CAM[index])) > 5.0
        np.testing.assert_allclose(_blob_centre(sequence.read_rgb(index)), expected, atol=0.5)
    assert sequence.timestamp_ns.tolist() == [0, 33_333_333, 66_666_666, 99_999_999]


def test_hot3d_trajectory_is_stage_2_with_the_first_camera_as_world(tmp_path: Path) -> None:
    """Camera poses are the clip's T_world_from_camera, re-based so frame 0 is the identity."""
    clip, mano, poses = _flat_right_clip(tmp_path)
    sequence = next(iter_hot3d([tmp_path], mano, keep_mano=False))
    assert sequence.has_camera_trajectory and sequence.mano_cam is None
    assert sequence.sequence_id == 'train_aria.clip-000001' and sequence.source == 'hot3d'
    np.testing.assert_allclose(sequence.T_world_cam[0], np.eye(4), atol=1e-9)
    for index in range(FRAMES):
        np.testing.assert_allclose(sequence.T_world_cam[index],
                                   np.linalg.inv(poses[0]) @ poses[index], atol=1e-9)
    world = transform_points(poses[3], sequence.joints_cam[3, RIGHT, :1])[0]
    expected = transform_points(poses[3], WRIST_CAM[3:])[0]
    np.testing.assert_allclose(world, expected, atol=1e-9)


def test_hot3d_kept_mano_of_both_hands_poses_to_the_camera_joints(tmp_path: Path) -> None:
    """Random world MANO of both hands, moved into the camera, re-poses to the camera joints."""
    rng = np.random.default_rng(22)
    mano = (hot3d_mano(rng, LEFT), hot3d_mano(rng, RIGHT))
    poses = random_poses(rng, FRAMES)
    hands = [{name: hot3d_hand(rng.normal(scale=0.3, size=15), rng.normal(size=6))
              for name in ('left', 'right')} for _ in range(FRAMES)]
    clip = hot3d_clip(tmp_path, poses, hands, rng.normal(size=10))
    sequence = read_hot3d_clip(clip, mano, keep_mano=True)
    assert sequence.hand_present.all()
    for side in (LEFT, RIGHT):
        model = ManoHandModel(mano[side], dtype=torch.float64)
        posed = model(*(torch.as_tensor(sequence.mano_cam[name][:, side]) for name in
                        ('global_orient', 'hand_pose', 'betas', 'transl'))).joints.numpy()
        np.testing.assert_allclose(posed, sequence.joints_cam[:, side], atol=1e-8)
    assert not np.allclose(sequence.joints_cam[:, LEFT], sequence.joints_cam[:, RIGHT])


def test_hot3d_quest3_grey_stream_in_an_extracted_folder(tmp_path: Path) -> None:
    """A Quest 3 clip (grey 1201-1 only) extracted to a folder reads as three equal channels."""
    clip, mano, _ = _flat_right_clip(tmp_path, stream='1201-1', as_tar=False)
    sequence = next(iter_hot3d([clip], mano, keep_mano=False))
    rgb = sequence.read_rgb(3)
    assert rgb.shape == (HOT3D_SIZE, HOT3D_SIZE, 3)
    assert np.array_equal(rgb[..., 0], rgb[..., 2])
    expected = project_points(WRIST_CAM[3:], sequence.K[3])[0]
    np.testing.assert_allclose(_blob_centre(rgb), expected, atol=0.5)


def test_hot3d_needs_mano_and_skips_unannotated_clips(tmp_path: Path) -> None:
    """Without MANO files the flag is an InputError; a clip without hands.json is skipped."""
    rng = np.random.default_rng(23)
    mano = (hot3d_mano(rng, LEFT), hot3d_mano(rng, RIGHT))
    hot3d_clip(tmp_path, random_poses(rng, 2), [None, None], np.zeros(10))
    with pytest.raises(InputError, match='MANO'):
        ADAPTERS['hot3d']([tmp_path], AdapterContext())
    assert list(ADAPTERS['hot3d']([tmp_path], AdapterContext(mano, keep_mano=True))) == []


def test_hot3d_clip_builds_into_stage_2(tmp_path: Path) -> None:
    """Through the builder (real-MANO corpus) the clip is kept in Stage II with its joints."""
    clip, mano, _ = _flat_right_clip(tmp_path / 'in')
    models = tuple(ManoHandModel(mano[side], dtype=torch.float64) for side in (LEFT, RIGHT))
    manifest = build_corpus(iter_hot3d([clip], mano, keep_mano=True), tmp_path / 'out', models,
                            BuildSettings())
    assert len(manifest['stage_2']) == 1
    assert manifest['sources'] == [{'source': 'hot3d', 'licence': manifest['sources'][0][
        'licence']}]
