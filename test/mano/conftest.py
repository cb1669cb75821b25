"""Fixtures of the hand-model tests: fake MANO files written once per session."""

from pathlib import Path

from mano_builders import fake_mano_arrays
from mano_builders import write_fake_mano_pickle
import numpy as np
import pytest

#: Seed of the fake MANO arrays (independent of the per-test ``rng``).
FAKE_MANO_SEED = 2017


@pytest.fixture(scope='session')
def fake_mano_arrays_right() -> dict[str, object]:
    """Return the fake right-hand arrays written to ``fake_mano_dir``."""
    return fake_mano_arrays(np.random.default_rng(FAKE_MANO_SEED))


@pytest.fixture(scope='session')
def fake_mano_dir(tmp_path_factory: pytest.TempPathFactory,
                  fake_mano_arrays_right: dict[str, object]) -> Path:
    """Return a folder with fake MANO_RIGHT.pkl and MANO_LEFT.pkl.

    The left file repeats the right file's shapedirs, like the official files (smplx issue #48).
    """
    folder = tmp_path_factory.mktemp('mano')
    write_fake_mano_pickle(folder / 'MANO_RIGHT.pkl', fake_mano_arrays_right)
    left = fake_mano_arrays(np.random.default_rng(FAKE_MANO_SEED + 1))
    left['shapedirs'] = fake_mano_arrays_right['shapedirs']
    write_fake_mano_pickle(folder / 'MANO_LEFT.pkl', left)
    return folder
