"""Training samples: the written directory loads back through the PyTorch dataset."""

import json
import os
from pathlib import Path

from infinihand_ros.core.errors import InputError
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.corpus.sample_dataset import SampleDataset
from infinihand_ros.synth.sample_sink import SampleSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
import torch


@pytest.fixture(scope='module')
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    """Write a three-frame sample directory; return it with the frames it was written from."""
    root = tmp_path_factory.mktemp('samples') / 'seq'
    sequence = SyntheticSequence(SynthConfig(width=96, height=72), seed=4, num_frames=3)
    frames = list(sequence)
    with SampleSink(root, sequence.describe()) as sink:
        for frame in frames:
            sink.add(frame)
    return root, frames


def test_dataset_returns_the_ground_truth(written: tuple[Path, list]) -> None:
    root, frames = written
    dataset = SampleDataset(root)
    assert len(dataset) == len(frames)
    for index, frame in enumerate(frames):
        item = dataset[index]
        assert item['rgb'].dtype == torch.uint8 and item['rgb'].shape == (72, 96, 3)
        # JPEG at quality 95: small per-pixel differences only.
        assert np.abs(item['rgb'].numpy().astype(int) - frame.rgb).mean() < 4.0
        assert item['timestamp_ns'].item() == frame.timestamp_ns
        np.testing.assert_allclose(item['T_world_cam'].numpy(), frame.camera_pose.matrix())
        for hand in frame.hands:
            s = hand.side
            assert bool(item['hand_present'][s]) and bool(item['visible'][s]) == hand.visible
            np.testing.assert_array_equal(item['masks'][s].numpy(), hand.mask)
            np.testing.assert_allclose(item['joints_cam'][s].numpy(), hand.joints_cam)
            np.testing.assert_allclose(item['mano_world_transl'][s].numpy(),
                                       hand.mano_world.transl)
        finite = np.isfinite(frame.depth)
        np.testing.assert_allclose(item['depth'].numpy()[finite], frame.depth[finite], atol=6e-4)
        assert np.all(item['depth'].numpy()[~finite] == 0)


def test_meta_names_the_format(written: tuple[Path, list]) -> None:
    meta = json.loads((written[0] / fmt.META_FILE).read_text())
    assert meta['format'] == fmt.FORMAT_NAME and meta['frames'] == 3
    assert meta['sequence']['seed'] == 4


def test_files_are_readable_by_others_as_the_umask_says(written: tuple[Path, list]) -> None:
    """No file stays private (safetensors creates 0600): datasets are shared on servers."""
    umask = os.umask(0o022)
    os.umask(umask)
    for path in (written[0] / fmt.ANNOTATIONS_FILE, written[0] / fmt.META_FILE):
        assert path.stat().st_mode & 0o777 == 0o666 & ~umask, path.name


def test_bad_directory_is_reported(tmp_path: Path) -> None:
    with pytest.raises(InputError, match='not a readable sample directory'):
        SampleDataset(tmp_path)
    (tmp_path / fmt.META_FILE).write_text(json.dumps({'format': 'other', 'version': 1}))
    with pytest.raises(InputError, match="format 'other'"):
        SampleDataset(tmp_path)
