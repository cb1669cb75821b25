"""Tests of train/horizontal_flip.py: a mirrored clip is the same task, sides swapped."""

from collections.abc import Callable
from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.synth.sequence import mask_box
from infinihand_ros.train import sequence_reader as keys
from infinihand_ros.train.clip_data import ClipDataset
from infinihand_ros.train.clip_data import collate_clips
from infinihand_ros.train.horizontal_flip import draw_flips
from infinihand_ros.train.horizontal_flip import flip_clips
from infinihand_ros.train.horizontal_flip import mirror_clip_batch
from infinihand_ros.train.train_config import ClipLayout
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.trainer import train
import numpy as np
import pytest
import torch
from train_builders import micro_geometry

LAYOUT = ClipLayout(anchor_frames=2, window_frames=2, num_windows=1, frame_stride=1,
                    clip_step=2)


@pytest.fixture(scope='module')
def batch(sequence_dirs: list[Path]) -> dict[str, torch.Tensor]:
    """Two clips (one per test sequence) as a training batch."""
    dataset = ClipDataset(sequence_dirs, LAYOUT, micro_geometry())
    return collate_clips([dataset[0], dataset[len(dataset) - 1]])


def _project(points: torch.Tensor, intrinsics: torch.Tensor) -> torch.Tensor:
    """Pixels of (B, S, 2, 21, 3) camera points under (B, S, 3, 3) K."""
    projected = points @ intrinsics[:, :, None].transpose(-1, -2)
    return projected[..., :2] / projected[..., 2:]


def test_mirrored_targets_stay_consistent_with_each_other(batch: dict) -> None:
    """Mirrored 3D joints project onto the mirrored 2D joints, and map to the mirrored world."""
    mirrored = mirror_clip_batch(batch)
    present = mirrored[keys.HAND_PRESENT]
    assert bool(present.any())
    torch.testing.assert_close(
        _project(mirrored[keys.JOINTS_CAM], mirrored[keys.INTRINSICS])[present],
        mirrored[keys.JOINTS_2D][present], atol=1e-6, rtol=0)
    pose = mirrored[keys.T_WORLD_CAM][:, :, None]
    world = mirrored[keys.JOINTS_CAM] @ pose[..., :3, :3].transpose(-1, -2) \
        + pose[..., None, :3, 3]
    torch.testing.assert_close(world[present], mirrored[keys.JOINTS_WORLD][present])
    assert torch.allclose(torch.linalg.det(mirrored[keys.T_WORLD_CAM][..., :3, :3]),
                          torch.ones(()).double())
    torch.testing.assert_close(mirrored[keys.FOV], batch[keys.FOV])


def test_sides_swap_and_the_images_mirror(batch: dict) -> None:
    """The left hand's targets become the right hand's, mirrored; images read right to left."""
    mirrored = mirror_clip_batch(batch)
    assert torch.equal(mirrored[keys.IMAGES], batch[keys.IMAGES].flip(-1))
    assert torch.equal(mirrored[keys.MASKS][:, :, 1], batch[keys.MASKS][:, :, 0].flip(-1))
    assert torch.equal(mirrored[keys.HAND_PRESENT][:, :, 0], batch[keys.HAND_PRESENT][:, :, 1])
    left = batch[keys.JOINTS_CAM][:, :, 0]
    torch.testing.assert_close(mirrored[keys.JOINTS_CAM][:, :, 1],
                               left * torch.tensor([-1.0, 1.0, 1.0], dtype=left.dtype))
    width = batch[keys.IMAGES].shape[-1]
    u = batch[keys.JOINTS_2D][:, :, 0, :, 0]
    torch.testing.assert_close(mirrored[keys.JOINTS_2D][:, :, 1, :, 0], width - 1.0 - u)


def test_mirrored_boxes_are_the_boxes_of_the_mirrored_masks(batch: dict) -> None:
    """A tight box (exclusive ends) of a mirrored mask is the mirrored tight box."""
    masks = batch[keys.MASKS] > 0
    mirrored = mirror_clip_batch({keys.IMAGES: batch[keys.IMAGES],
                                  keys.MASKS: batch[keys.MASKS],
                                  keys.BOXES: torch.from_numpy(np.stack(
                                      [[[mask_box(side.numpy()) for side in frame]
                                        for frame in clip] for clip in masks])).float()})
    flipped = mirrored[keys.MASKS] > 0
    expected = np.stack([[[mask_box(side.numpy()) for side in frame] for frame in clip]
                         for clip in flipped])
    has_pixels = flipped.flatten(-2).any(-1)
    assert bool(has_pixels.any())
    np.testing.assert_array_equal(mirrored[keys.BOXES].numpy()[has_pixels.numpy()],
                                  expected[has_pixels.numpy()])


def test_mirrored_mano_gives_the_mirrored_joints_with_the_other_hand_model(batch: dict) -> None:
    """The built-in left model on mirrored right-hand MANO is the mirror of the right hand."""
    mirrored = mirror_clip_batch(batch)
    for data in (batch, mirrored):
        present = data[keys.HAND_PRESENT]
        for side in (0, 1):
            rows = present[:, :, side]
            if not bool(rows.any()):
                continue
            params = [data[f'mano_{name}'][:, :, side][rows].float()
                      for name in ('global_orient', 'hand_pose', 'betas', 'transl')]
            joints = BuiltinHandModel(side)(*params).joints
            torch.testing.assert_close(joints, data[keys.JOINTS_CAM][:, :, side][rows].float(),
                                       atol=1e-5, rtol=0)


def test_mirroring_twice_is_the_identity_and_only_chosen_clips_change(batch: dict) -> None:
    twice = mirror_clip_batch(mirror_clip_batch(batch))
    for key, value in batch.items():
        torch.testing.assert_close(twice[key], value, equal_nan=True)
    flips = torch.tensor([False, True])
    out = flip_clips(batch, flips)
    mirrored = mirror_clip_batch(batch)
    for key, value in batch.items():
        torch.testing.assert_close(out[key][0], value[0], equal_nan=True)
        torch.testing.assert_close(out[key][1], mirrored[key][1], equal_nan=True)
    assert flip_clips(batch, torch.tensor([False, False])) is batch


def test_unknown_keys_and_bad_probabilities_are_refused(batch: dict,
                                                        write_run_config: Callable[..., Path]
                                                        ) -> None:
    with pytest.raises(InputError, match="'extra'"):
        mirror_clip_batch({**batch, 'extra': torch.zeros(2)})
    with pytest.raises(ConfigError, match='horizontal_flip'):
        load_train_config(write_run_config(horizontal_flip=1.5))
    draws = draw_flips(1000, 0.5, torch.Generator().manual_seed(0))
    assert 400 < int(draws.sum()) < 600
    assert not bool(draw_flips(10, 0.0, torch.Generator()).any())


def test_a_run_with_flips_trains_other_clips_and_resumes_bit_for_bit(
        write_run_config: Callable[..., Path], tmp_path: Path) -> None:
    """Flips reach the step (losses differ from a plain run) and resume exactly (2 + 2 == 4).

    With probability 0.5 the resumed half only repeats if the checkpoint kept the draws.
    """
    plain = load_train_config(write_run_config(steps=2, checkpoint_every=100))
    flipped = load_train_config(write_run_config(steps=4, checkpoint_every=2,
                                                 horizontal_flip=0.5))
    assert flipped.horizontal_flip == 0.5
    whole = train(flipped, tmp_path / 'whole', progress=False)
    assert train(plain, tmp_path / 'plain', progress=False).losses != whole.losses[:2]
    train(flipped, tmp_path / 'split', stop_after=2, progress=False)
    second = train(flipped, tmp_path / 'split', resume=tmp_path / 'split', progress=False)
    assert second.losses == whole.losses[2:]
