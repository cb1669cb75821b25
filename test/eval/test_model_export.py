"""Tests of eval/model_export.py: half-precision storage, the mean pose, loading back."""

import json
from pathlib import Path

from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import ModelSelection
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.eval.baselines import mean_articulation
from infinihand_ros.eval.model_export import export_model
from infinihand_ros.eval.model_export import main
from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import CameraHeadConfig
from infinihand_ros.model.config import DptConfig
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import MemoryConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.io.bundled import MEAN_POSE_FILE
from infinihand_ros.model.io.checkpoint import read_checkpoint
from infinihand_ros.model.io.checkpoint import save_infinihand_checkpoint
from infinihand_ros.synth.sample_sink import SampleSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
import torch


@pytest.fixture
def model() -> InfiniHandModel:
    """Return a seeded micro InfiniHand model: 4 x 5 patches, the tiny hand branch."""
    aggregator = AggregatorConfig(image_height=56, image_width=70, embed_dim=64, depth=2,
                                  num_heads=2, rope3d_split=(12, 10, 10),
                                  selected_layers=(0, 1, 1, 1))
    geometry = GeometryConfig(aggregator=aggregator,
                              camera_head=CameraHeadConfig(trunk_depth=1, num_heads=2,
                                                           num_iterations=2),
                              dpt=DptConfig(features=16, out_channels=(16, 16, 32, 32),
                                            head_features=8),
                              memory=MemoryConfig(anchor_frames=1, window=2))
    return build_infinihand_model(geometry, load_hand_branch_config('tiny'), seed=0).eval()


@pytest.fixture(scope='module')
def train_sequence(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SyntheticSequence]:
    sequence = SyntheticSequence(SynthConfig(width=64, height=48), seed=4, num_frames=6)
    path = tmp_path_factory.mktemp('train') / 'seq' / 'samples'
    with SampleSink(path, sequence.describe()) as sink:
        for frame in sequence:
            sink.add(frame)
    return path, sequence


def test_export_halves_storage_and_loads_back_within_float16(
        model: InfiniHandModel, train_sequence: tuple[Path, SyntheticSequence],
        tmp_path: Path) -> None:
    source = save_infinihand_checkpoint(model, tmp_path / 'full')
    out = export_model(source, tmp_path / 'bundled', [str(train_sequence[0])])
    exported = read_checkpoint(out)
    full = read_checkpoint(source)
    for key, tensor in exported.tensors.items():
        original = full.tensors[key]
        if original.is_floating_point():
            assert tensor.dtype == torch.float16, key
            torch.testing.assert_close(tensor.float(), original.float(), rtol=1e-3, atol=1e-4)
        else:
            assert torch.equal(tensor, original), key
    size = (out / 'model.safetensors').stat().st_size
    assert size < 0.55 * (source / 'model.safetensors').stat().st_size
    built = build_model(EngineConfig(model=ModelSelection(checkpoint=str(out))))
    weight = next(iter(built.parameters()))
    assert weight.dtype == torch.float32


def test_mean_pose_is_the_training_hands_mean(
        model: InfiniHandModel, train_sequence: tuple[Path, SyntheticSequence],
        tmp_path: Path) -> None:
    path, sequence = train_sequence
    source = save_infinihand_checkpoint(model, tmp_path / 'full')
    assert main(['--checkpoint', str(source), '--out', str(tmp_path / 'bundled'),
                 '--train-sequences', str(path)]) == 0
    stored = json.loads((tmp_path / 'bundled' / MEAN_POSE_FILE).read_text())
    expected = mean_articulation([t.hand_pose for t in sequence.tracks],
                                 [t.side for t in sequence.tracks])
    np.testing.assert_allclose(stored['hand_pose'], expected, atol=1e-9)
    assert stored['hands'] == 6 * len(sequence.tracks)
    assert main(['--checkpoint', str(tmp_path / 'missing'), '--out', str(tmp_path / 'x'),
                 '--train-sequences', str(path)]) == 2
