"""Fixtures of the converter tests: one torch thread and tiny synthetic bags built once."""

from pathlib import Path

from convert_builders import synth_bag
import pytest
import torch


@pytest.fixture(scope='session', autouse=True)
def one_torch_thread() -> None:
    """Keep the engine on one thread (the tests run beside other jobs)."""
    torch.set_num_threads(1)


@pytest.fixture(scope='session')
def synth_bags(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Return two 6-frame 160x120 synthetic bags (raw rgb8 and jpeg CompressedImage)."""
    root = tmp_path_factory.mktemp('synth')
    return [synth_bag(root / 'raw', 1, 6),
            synth_bag(root / 'jpeg', 2, 6, '--image-codec', 'jpeg', '--format', 'sqlite3')]
