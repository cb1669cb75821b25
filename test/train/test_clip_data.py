"""Training clips: targets at the model size, deterministic resumable order, workers agree."""

import json
from pathlib import Path

from infinihand_ros.core.errors import InputError
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.train import sequence_reader as keys
from infinihand_ros.train.clip_data import ClipDataset
from infinihand_ros.train.clip_data import ClipLoader
from infinihand_ros.train.sequence_reader import build_targets
from infinihand_ros.train.sequence_reader import find_sequences
from infinihand_ros.train.sequence_reader import open_sequence
from infinihand_ros.train.train_config import ClipLayout
import numpy as np
import pytest
import torch
from train_builders import micro_geometry
from train_builders import SEQUENCES

LAYOUT = ClipLayout(anchor_frames=2, window_frames=2, num_windows=1, frame_stride=1,
                    clip_step=2)


@pytest.fixture(scope='module')
def dataset(sequence_dirs: list[Path]) -> ClipDataset:
    return ClipDataset(sequence_dirs, LAYOUT, micro_geometry())


def test_clips_cover_every_sequence(dataset: ClipDataset) -> None:
    # Starts 0, 2, ... with room for 4 frames: 10 frames -> 4 clips, 8 frames -> 3 clips.
    assert len(dataset) == sum(len(range(0, frames - 3, 2)) for _, frames in SEQUENCES)
    item = dataset[len(dataset) - 1]
    assert int(item[keys.SEQUENCE_INDEX]) == 1
    assert item[keys.FRAME_INDEX].tolist() == [4, 5, 6, 7]
    assert item[keys.IMAGES].shape == (4, 3, 56, 70) and item[keys.IMAGES].dtype == torch.uint8
    assert item[keys.MASKS].shape == (4, 2, 56, 70)
    assert bool(item[keys.MASK_VALID].all())


def test_targets_are_mapped_to_the_model_input(dataset: ClipDataset) -> None:
    """Joints projected with the model-size K land on the model-size 2D joints and boxes."""
    item = dataset[0]
    joints, intrinsics = item[keys.JOINTS_CAM], item[keys.INTRINSICS]
    projected = joints @ intrinsics[:, None].transpose(-1, -2)
    pixels = projected[..., :2] / projected[..., 2:]
    present = item[keys.HAND_PRESENT]
    torch.testing.assert_close(pixels[present], item[keys.JOINTS_2D][present], atol=1e-6,
                               rtol=0)
    valid = item[keys.BOX_VALID]
    assert bool(valid.any())
    boxes = item[keys.BOXES][valid]
    assert bool((boxes[:, 2:] > boxes[:, :2]).all() and (boxes >= -1).all())
    assert bool((boxes[:, [0, 2]] <= 71).all() and (boxes[:, [1, 3]] <= 57).all())
    fov_h = 2 * torch.atan(28.0 / intrinsics[:, 1, 1])
    torch.testing.assert_close(item[keys.FOV][:, 0], fov_h)
    masks = item[keys.MASKS]
    assert bool((masks[:, :, [0, -1]] == 0).all())  # letterbox rows (96 x 72 -> 70 x 52)


def test_depth_is_metric_at_the_model_size_and_zero_in_the_padding(
        dataset: ClipDataset, sequence_dirs: list[Path]) -> None:
    """The clip depth is the source depth (mm PNG -> m) resized nearest into the content box."""
    item = dataset[0]
    depth = item[keys.DEPTH]
    assert depth.shape == (4, 56, 70) and depth.dtype == torch.float32
    reader = open_sequence(sequence_dirs[0])
    source = reader.read_depth(0)
    x0, y0, x1, y1 = dataset.fitter.mapping(reader.image_size).content_box
    assert bool((depth[0, :y0] == 0).all() and (depth[0, y1:] == 0).all())
    inside = depth[0, y0:y1, x0:x1]
    assert 0.0 < float(inside.max()) <= float(source.max())
    # Nearest resizing keeps values: every model depth is one of the source depths.
    assert set(np.unique(inside.numpy())) <= set(np.unique(source))


def test_missing_annotations_read_as_invalid(sequence_dirs: list[Path]) -> None:
    reader = open_sequence(sequence_dirs[0])
    annotations = reader.annotations()
    assert annotations['K'].shape == (SEQUENCES[0][1], 3, 3)

    class WithoutCameras:
        num_frames, image_size = reader.num_frames, reader.image_size

        def annotations(self) -> dict:
            return {key: value for key, value in annotations.items() if key != 'T_world_cam'}

    targets = build_targets(WithoutCameras(), micro_geometry(), has_masks=False)
    assert not targets[keys.CAMERA_VALID].any() and not targets[keys.MASK_VALID].any()
    assert np.isnan(targets[keys.T_WORLD_CAM]).all()


def test_sequences_are_found_below_folders(sequence_dirs: list[Path], tmp_path: Path) -> None:
    root = sequence_dirs[0].parent.parent
    assert find_sequences([str(root)]) == sorted(sequence_dirs)
    with pytest.raises(InputError, match='no such directory'):
        find_sequences([str(tmp_path / 'none')])
    with pytest.raises(InputError, match='no sequence directory'):
        find_sequences([str(tmp_path)])


def test_unknown_formats_and_short_sequences_are_refused(sequence_dirs: list[Path],
                                                         tmp_path: Path) -> None:
    (tmp_path / fmt.META_FILE).write_text(json.dumps({'format': 'other'}), encoding='utf-8')
    with pytest.raises(InputError, match="format 'other' has no reader"):
        open_sequence(tmp_path)
    with pytest.raises(InputError, match='no sequence holds a clip of 41 frames'):
        ClipDataset(sequence_dirs, ClipLayout(anchor_frames=41, num_windows=0),
                    micro_geometry())


def _sequence_of(loader: ClipLoader, first_step: int, count: int) -> list[list[int]]:
    batches = loader.batches(first_step)
    order = []
    for _ in range(count):
        batch = next(batches)
        order.append(list(zip(batch[keys.SEQUENCE_INDEX].tolist(),
                              batch[keys.FRAME_INDEX][:, 0].tolist())))
    batches.close()
    return order


def test_order_is_seeded_resumable_and_worker_independent(dataset: ClipDataset) -> None:
    loader = ClipLoader(dataset, batch_size=2, num_workers=0, seed=7)
    assert loader.batches_per_epoch == len(dataset) // 2
    full = _sequence_of(loader, 0, 5)  # crosses into the second epoch
    assert _sequence_of(loader, 2, 3) == full[2:]
    assert _sequence_of(ClipLoader(dataset, 2, num_workers=2, seed=7), 0, 5) == full
    assert _sequence_of(ClipLoader(dataset, 2, num_workers=0, seed=8), 0, 5) != full
    epoch = [clip for batch in full[:loader.batches_per_epoch] for clip in batch]
    assert len(set(epoch)) == len(epoch)


def test_replicas_read_disjoint_clips(dataset: ClipDataset) -> None:
    first = _sequence_of(ClipLoader(dataset, 1, 0, seed=1, num_replicas=2, rank=0), 0, 3)
    second = _sequence_of(ClipLoader(dataset, 1, 0, seed=1, num_replicas=2, rank=1), 0, 3)
    assert not {clip for batch in first for clip in batch} & {
        clip for batch in second for clip in batch}
    with pytest.raises(InputError, match='give no batch of 100'):
        ClipLoader(dataset, 100, 0, seed=1)


def test_cached_frames_equal_decoded_frames(dataset: ClipDataset,
                                            sequence_dirs: list[Path]) -> None:
    cached = ClipDataset(sequence_dirs, LAYOUT, micro_geometry(), cache_images=True)
    for _ in range(2):  # the second read comes from the cache
        for key, value in cached[1].items():
            torch.testing.assert_close(value, dataset[1][key], msg=key)
