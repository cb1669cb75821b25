"""Tests of the chumpy-free MANO file loader on fake files in the official layout."""

import dataclasses
import os
from pathlib import Path
import pickle
import sys

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.mano.mano_file import fix_left_shapedirs
from infinihand_ros.mano.mano_file import load_mano_data
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_file import save_mano_npz
from mano_builders import fake_mano_arrays
from mano_builders import ROOT_PARENT_UINT32
from mano_builders import write_fake_mano_pickle
import numpy as np
import pytest


class _CallsGetcwd:
    """An object whose pickle names a function (os.getcwd) to run on load."""

    def __reduce__(self) -> tuple:
        return os.getcwd, ()


def test_official_layout_pickle_loads_without_chumpy(
        fake_mano_dir: Path, fake_mano_arrays_right: dict[str, object]) -> None:
    assert 'chumpy' not in sys.modules
    data = load_mano_data(fake_mano_dir / 'MANO_RIGHT.pkl')
    assert 'chumpy' not in sys.modules
    assert data.side == RIGHT and data.source.endswith('MANO_RIGHT.pkl')
    np.testing.assert_array_equal(data.v_template, fake_mano_arrays_right['v_template'])
    np.testing.assert_array_equal(data.posedirs, fake_mano_arrays_right['posedirs'])
    np.testing.assert_array_equal(data.joint_regressor,
                                  fake_mano_arrays_right['J_regressor'].toarray())
    assert data.kintree_table[0].tolist() == [-1, *MANO_PARENTS[1:]]
    assert data.faces.dtype == np.int64 and data.shapedirs.dtype == np.float64
    assert load_mano_data(fake_mano_dir / 'MANO_LEFT.pkl').side == LEFT


def test_legacy_module_names_of_python2_pickles_load(tmp_path: Path,
                                                     fake_mano_dir: Path) -> None:
    # Files written with numpy 1.x / old scipy name numpy.core.* and scipy.sparse.csc.
    content = (fake_mano_dir / 'MANO_RIGHT.pkl').read_bytes()
    legacy = content.replace(b'numpy._core.', b'numpy.core.')
    legacy = legacy.replace(b'scipy.sparse._csc', b'scipy.sparse.csc')
    assert legacy != content
    path = tmp_path / 'MANO_RIGHT.pkl'
    path.write_bytes(legacy)
    np.testing.assert_array_equal(load_mano_data(path).joint_regressor,
                                  load_mano_data(fake_mano_dir / 'MANO_RIGHT.pkl').joint_regressor)


def test_npz_round_trip_and_explicit_side(tmp_path: Path, fake_mano_dir: Path) -> None:
    data = load_mano_data(fake_mano_dir / 'MANO_LEFT.pkl')
    save_mano_npz(data, tmp_path / 'converted.npz')
    with pytest.raises(CheckpointError, match='cannot tell the hand side from the file name'):
        load_mano_data(tmp_path / 'converted.npz')
    loaded = load_mano_data(tmp_path / 'converted.npz', side=LEFT)
    for field in ('v_template', 'shapedirs', 'weights', 'faces', 'hands_mean'):
        np.testing.assert_array_equal(getattr(loaded, field), getattr(data, field))


def test_missing_and_corrupt_files_raise_checkpoint_error(tmp_path: Path) -> None:
    missing = tmp_path / 'MANO_RIGHT.pkl'
    with pytest.raises(CheckpointError, match=r'MANO_RIGHT\.pkl: MANO file not found; download'):
        load_mano_data(missing)
    missing.write_bytes(b'\x80\x02this is not a pickle')
    with pytest.raises(CheckpointError, match=r'MANO_RIGHT\.pkl: not a readable MANO pickle'):
        load_mano_data(missing)
    npz = tmp_path / 'MANO_RIGHT.npz'
    npz.write_bytes(b'garbage')
    with pytest.raises(CheckpointError, match=r'MANO_RIGHT\.npz: not a readable MANO \.npz'):
        load_mano_data(npz)
    missing.write_bytes(pickle.dumps([1, 2, 3], protocol=2))
    with pytest.raises(CheckpointError, match='expected a dict of MANO arrays, got list'):
        load_mano_data(missing)


def test_pickles_naming_other_code_are_refused(tmp_path: Path,
                                               rng: np.random.Generator) -> None:
    arrays = fake_mano_arrays(rng)
    arrays['hands_mean'] = _CallsGetcwd()
    path = tmp_path / 'MANO_RIGHT.pkl'
    path.write_bytes(pickle.dumps(arrays, protocol=2))
    with pytest.raises(CheckpointError, match=r'global posix\.getcwd is not allowed'):
        load_mano_data(path)


@pytest.mark.parametrize(('key', 'value', 'message'), [
    ('shapedirs', np.zeros((778, 3, 9)), r'shapedirs has shape \(778, 3, 9\), expected '
                                         r'\(778, 3, 10\); download MANO_RIGHT\.pkl'),
    ('f', np.zeros((1538, 2)), r'faces has shape \(1538, 2\)'),
    ('f', np.full((1538, 3), 778), r'faces index vertices outside \[0, 778\)'),
    ('kintree_table', np.array([[ROOT_PARENT_UINT32] + [0] * 15, range(16)]),
     'kintree_table parents .* are not the MANO parents'),
    ('weights', np.full((778, 16), np.nan), 'NaN or infinite'),
    ('hands_mean', None, 'missing MANO keys'),
])
def test_malformed_arrays_raise_checkpoint_error(tmp_path: Path, rng: np.random.Generator,
                                                 key: str, value: object, message: str) -> None:
    arrays = fake_mano_arrays(rng)
    if value is None:
        del arrays[key]
    else:
        arrays[key] = value
    path = write_fake_mano_pickle(tmp_path / 'MANO_RIGHT.pkl', arrays)
    with pytest.raises(CheckpointError, match=message):
        load_mano_data(path)


def test_chumpy_object_without_a_value_is_reported(tmp_path: Path,
                                                   rng: np.random.Generator) -> None:
    arrays = fake_mano_arrays(rng)
    path = write_fake_mano_pickle(tmp_path / 'MANO_RIGHT.pkl', arrays)
    # Rename the stored value key so that the Ch state has no 'x' (e.g. a chumpy expression).
    path.write_bytes(path.read_bytes().replace(b'\x8c\x01x', b'\x8c\x01y').replace(
        b'X\x01\x00\x00\x00x', b'X\x01\x00\x00\x00y'))
    with pytest.raises(CheckpointError, match="chumpy chumpy.ch.Ch without a stored value 'x'"):
        load_mano_data(path)


def test_left_shapedirs_bug_is_fixed_only_when_present(fake_mano_dir: Path) -> None:
    right = load_mano_data(fake_mano_dir / 'MANO_RIGHT.pkl')
    left = load_mano_data(fake_mano_dir / 'MANO_LEFT.pkl')  # built with the right's shapedirs
    fixed = fix_left_shapedirs(left, right)
    np.testing.assert_array_equal(fixed.shapedirs[:, 0], -right.shapedirs[:, 0])
    np.testing.assert_array_equal(fixed.shapedirs[:, 1:], right.shapedirs[:, 1:])
    assert fix_left_shapedirs(fixed, right) is fixed
    with pytest.raises(CheckpointError, match='needs a left and a right model'):
        fix_left_shapedirs(right, left)


def test_mano_data_rejects_a_bad_side(fake_mano_dir: Path) -> None:
    data = load_mano_data(fake_mano_dir / 'MANO_RIGHT.pkl')
    with pytest.raises(ValueError, match='hand side must be 0'):
        dataclasses.replace(data, side=3)
    assert isinstance(dataclasses.replace(data, side=LEFT), ManoData)
