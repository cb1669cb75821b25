"""Fixtures of the training tests: micro model files, synthetic sequences, micro run configs."""

from collections.abc import Callable
from pathlib import Path

from infinihand_ros.core.config import dump_config
from infinihand_ros.synth.sample_sink import SampleSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import pytest
from train_builders import micro_geometry
from train_builders import MICRO_HAND_BRANCH
from train_builders import run_settings
from train_builders import SEQUENCES
from train_builders import SOURCE_SIZE
import yaml


@pytest.fixture(scope='session')
def model_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Return the (geometry, hand branch) YAML files of the micro model."""
    folder = tmp_path_factory.mktemp('micro_model')
    geometry, hand = folder / 'geometry.yaml', folder / 'hand_branch.yaml'
    geometry.write_text(dump_config(micro_geometry(), 'geometry'), encoding='utf-8')
    hand.write_text(yaml.safe_dump({'hand_branch': MICRO_HAND_BRANCH}), encoding='utf-8')
    return geometry, hand


@pytest.fixture(scope='session')
def sequence_dirs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Write the test sequences in the training-sample form; return their directories."""
    folder = tmp_path_factory.mktemp('sequences')
    width, height = SOURCE_SIZE
    paths = []
    for seed, frames in SEQUENCES:
        sequence = SyntheticSequence(SynthConfig(width=width, height=height), seed=seed,
                                     num_frames=frames)
        path = folder / f'seq_{seed}' / 'samples'
        with SampleSink(path, sequence.describe()) as sink:
            for frame in sequence:
                sink.add(frame)
        paths.append(path)
    return paths


@pytest.fixture
def write_run_config(tmp_path: Path, model_files: tuple[Path, Path],
                     sequence_dirs: list[Path]) -> Callable[..., Path]:
    """Return ``write(name, **overrides) -> path`` of a micro run config YAML."""
    def write(name: str = 'run.yaml', **train: object) -> Path:
        path = tmp_path / name
        path.write_text(yaml.safe_dump({'train': run_settings(model_files, sequence_dirs,
                                                              **train)}), encoding='utf-8')
        return path

    return write
