"""Chumpy-free loading of the official MANO model files (MANO_RIGHT.pkl / MANO_LEFT.pkl).

The official pickles (Python 2, mano.is.tue.mpg.de) store some arrays as chumpy ``Ch``
objects, and chumpy does not import on numpy >= 1.24. This loader unpickles with
``encoding='latin1'`` and an allow-list of globals: numpy arrays load as usual, every
``chumpy.*`` class becomes a stub that keeps the pickled state (a ``Ch`` keeps its value under
``'x'``), and ``scipy.sparse`` matrices become stubs rebuilt into dense arrays, so neither chumpy
nor any code named by the file runs.
A pre-converted ``.npz`` with the same keys is read without pickle at all.

The licensed MANO files are never shipped, fetched or committed by this project: pass the path of
files you downloaded yourself.
"""

import dataclasses
from dataclasses import dataclass
import logging
from pathlib import Path
import pickle
from types import MappingProxyType
from typing import Any, Final

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import side_name
import numpy as np
import scipy.sparse

logger = logging.getLogger(__name__)

NUM_VERTICES: Final = 778
NUM_FACES: Final = 1538
NUM_POSE_FEATURES: Final = NUM_HAND_POSE_JOINTS * 9
NUM_POSE_PARAMS: Final = NUM_HAND_POSE_JOINTS * 3
#: File key -> ManoData field.
FILE_KEYS: Final = MappingProxyType({
    'v_template': 'v_template', 'shapedirs': 'shapedirs', 'posedirs': 'posedirs',
    'J_regressor': 'joint_regressor', 'weights': 'weights', 'kintree_table': 'kintree_table',
    'f': 'faces', 'hands_components': 'hands_components', 'hands_mean': 'hands_mean',
})
#: ManoData field -> expected shape.
FIELD_SHAPES: Final = MappingProxyType({
    'v_template': (NUM_VERTICES, 3), 'shapedirs': (NUM_VERTICES, 3, NUM_BETAS),
    'posedirs': (NUM_VERTICES, 3, NUM_POSE_FEATURES),
    'joint_regressor': (NUM_MANO_JOINTS, NUM_VERTICES), 'weights': (NUM_VERTICES, NUM_MANO_JOINTS),
    'kintree_table': (2, NUM_MANO_JOINTS), 'faces': (NUM_FACES, 3),
    'hands_components': (NUM_POSE_PARAMS, NUM_POSE_PARAMS), 'hands_mean': (NUM_POSE_PARAMS,),
})
MANO_URL: Final = 'https://mano.is.tue.mpg.de'
#: The official left file's shapedirs x-axis equals the right file's (smplx issue #48); a summed
#: absolute difference below this means the bug is present.
SHAPEDIRS_BUG_TOLERANCE: Final = 1.0
_CHUMPY_VALUE_KEY: Final = 'x'
_SPARSE_CLASSES: Final = ('csc_matrix', 'csr_matrix', 'coo_matrix')
_BUILTIN_NAMES: Final = frozenset({'object', 'set', 'frozenset', 'complex', 'slice', 'bytearray',
                                   'list', 'dict', 'tuple', 'int', 'float', 'bool', 'str'})
_ALLOWED_GLOBALS: Final = frozenset({
    ('copy_reg', '_reconstructor'), ('copyreg', '_reconstructor'), ('_codecs', 'encode'),
    ('numpy', 'ndarray'), ('numpy', 'dtype'),
    ('numpy._core.multiarray', '_reconstruct'), ('numpy._core.multiarray', 'scalar'),
    ('numpy._core.numeric', '_frombuffer'),
})
_FIX_HINT: Final = (f'download MANO_RIGHT.pkl / MANO_LEFT.pkl again from {MANO_URL} '
                    '(or pass a .npz converted from them)')


@dataclass(frozen=True)
class ManoData:
    """Arrays of one MANO hand model, validated (float64 unless noted).

    Attributes:
        v_template: (778, 3) rest vertices of the mean hand, metres.
        shapedirs: (778, 3, 10) shape blend shapes.
        posedirs: (778, 3, 135) pose blend shapes over the (R - I) features of joints 1-15.
        joint_regressor: (16, 778) joint regressor (dense).
        weights: (778, 16) skinning weights.
        kintree_table: (2, 16) int64 parents (root -1) and joint ids.
        faces: (1538, 3) int64 triangle vertex indices.
        hands_components: (45, 45) pose PCA basis (unused by the flat-hand layer).
        hands_mean: (45,) mean pose (unused: poses are relative to the flat hand).
        side: 0 left, 1 right.
        source: where the arrays came from (used in error messages).

    """

    v_template: np.ndarray
    shapedirs: np.ndarray
    posedirs: np.ndarray
    joint_regressor: np.ndarray
    weights: np.ndarray
    kintree_table: np.ndarray
    faces: np.ndarray
    hands_components: np.ndarray
    hands_mean: np.ndarray
    side: int
    source: str = '<memory>'

    def __post_init__(self) -> None:
        """Check shapes, dtypes, topology and finiteness; store float64 / int64 copies."""
        side_name(self.side)
        for field, shape in FIELD_SHAPES.items():
            value = np.asarray(getattr(self, field))
            if value.dtype == object or not np.issubdtype(value.dtype, np.number):
                raise CheckpointError(f'{self.source}: {field} is not numeric '
                                      f'(dtype {value.dtype}); {_FIX_HINT}')
            if value.shape != shape:
                raise CheckpointError(f'{self.source}: {field} has shape {value.shape}, '
                                      f'expected {shape}; {_FIX_HINT}')
            integer = field in ('kintree_table', 'faces')
            object.__setattr__(self, field, value.astype(np.int64 if integer else np.float64))
        self.kintree_table[0, 0] = -1  # files store the root's parent as -1 or as uint32 max
        self._check_topology()

    def _check_topology(self) -> None:
        parents = self.kintree_table[0]
        if tuple(parents.tolist()) != MANO_PARENTS:
            raise CheckpointError(f'{self.source}: kintree_table parents {parents.tolist()} are '
                                  f'not the MANO parents {list(MANO_PARENTS)}; {_FIX_HINT}')
        if self.faces.min() < 0 or self.faces.max() >= NUM_VERTICES:
            raise CheckpointError(f'{self.source}: faces index vertices outside '
                                  f'[0, {NUM_VERTICES}); {_FIX_HINT}')
        if not all(np.all(np.isfinite(getattr(self, f))) for f in FIELD_SHAPES):
            raise CheckpointError(f'{self.source}: the model holds NaN or infinite values; '
                                  f'{_FIX_HINT}')


class _PickledStub:
    """Stand-in for a chumpy or scipy.sparse object: keeps the pickled state, runs no code."""

    source = ''

    def __new__(cls, *args: Any, **kwargs: Any) -> '_PickledStub':
        """Create an empty stub, ignoring the constructor arguments of the pickled class."""
        return super().__new__(cls)

    def __setstate__(self, state: Any) -> None:
        """Keep the pickled state as it is."""
        self.state = state


class _ManoUnpickler(pickle.Unpickler):
    """Unpickler allowing only numpy arrays, stubbed chumpy / scipy.sparse and a few builtins."""

    def find_class(self, module: str, name: str) -> Any:
        if module == 'chumpy' or module.startswith('chumpy.') or (
                module.startswith('scipy.sparse') and name in _SPARSE_CLASSES):
            return type(name, (_PickledStub,), {'source': f'{module}.{name}'})
        if module.startswith('numpy.core.'):
            module = 'numpy._core.' + module.removeprefix('numpy.core.')
        if (module, name) in _ALLOWED_GLOBALS or (
                module in ('__builtin__', 'builtins') and name in _BUILTIN_NAMES):
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f'global {module}.{name} is not allowed in a MANO file')


def _dense_from_sparse(stub: _PickledStub) -> np.ndarray:
    """Rebuild a dense array from the pickled state of a scipy.sparse matrix."""
    state = stub.state
    shape = tuple(state.get('_shape', state.get('shape')))
    kind = type(stub).__name__
    if kind == 'coo_matrix':
        rows, cols = state['coords'] if 'coords' in state else (state['row'], state['col'])
        return scipy.sparse.coo_matrix((state['data'], (rows, cols)), shape=shape).toarray()
    build = scipy.sparse.csc_matrix if kind == 'csc_matrix' else scipy.sparse.csr_matrix
    return build((state['data'], state['indices'], state['indptr']), shape=shape).toarray()


def _to_array(value: Any, key: str, source: str) -> np.ndarray:
    """Turn one unpickled value (array, chumpy or sparse stub, sparse matrix) into an array."""
    if isinstance(value, _PickledStub):
        state = value.state
        if value.source.startswith('scipy.sparse'):
            try:
                return _dense_from_sparse(value)
            except (KeyError, TypeError, ValueError, AttributeError) as exc:
                raise CheckpointError(f'{source}: cannot rebuild sparse {key} ({exc}); '
                                      f'{_FIX_HINT}') from exc
        if not isinstance(state, dict) or _CHUMPY_VALUE_KEY not in state:
            found = sorted(state) if isinstance(state, dict) else type(state).__name__
            raise CheckpointError(
                f"{source}: {key} is a chumpy {value.source} without a stored value 'x' "
                f'(state: {found}); convert the file once where chumpy works (np.array of each '
                f'value, saved with np.savez) and pass the .npz, or {_FIX_HINT}')
        return _to_array(state[_CHUMPY_VALUE_KEY], key, source)
    if scipy.sparse.issparse(value):
        return value.toarray()
    return np.asarray(value)


def _read_pickle(path: Path) -> dict[str, Any]:
    try:
        with path.open('rb') as stream:
            content = _ManoUnpickler(stream, encoding='latin1').load()
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, IndexError,
            KeyError, TypeError, ValueError, UnicodeDecodeError) as exc:
        raise CheckpointError(f'{path}: not a readable MANO pickle ({type(exc).__name__}: '
                              f'{exc}); {_FIX_HINT}') from exc
    if not isinstance(content, dict):
        raise CheckpointError(f'{path}: expected a dict of MANO arrays, got '
                              f'{type(content).__name__}; {_FIX_HINT}')
    return content


def _read_npz(path: Path) -> dict[str, Any]:
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {key: archive[key] for key in archive.files}
    except (OSError, ValueError, EOFError) as exc:
        raise CheckpointError(f'{path}: not a readable MANO .npz ({exc}); {_FIX_HINT}') from exc


def _side_from_name(path: Path) -> int:
    stem = path.stem.upper()
    sides = [side for side, word in ((LEFT, 'LEFT'), (RIGHT, 'RIGHT')) if word in stem]
    if len(sides) != 1:
        raise CheckpointError(f'{path}: cannot tell the hand side from the file name; name it '
                              'MANO_LEFT / MANO_RIGHT or pass side=0 (left) / side=1 (right)')
    return sides[0]


def load_mano_data(path: str | Path, side: int | None = None) -> ManoData:
    """Load an official MANO pickle, or a .npz with the same keys, without chumpy.

    Args:
        path: ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` (or a converted ``.npz``) you downloaded.
        side: 0 left or 1 right; by default read from the file name (LEFT / RIGHT).

    Returns:
        The validated model arrays.

    Raises:
        CheckpointError: for a missing, unreadable or malformed file, naming the path and the fix.

    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise CheckpointError(f'{path}: MANO file not found; {_FIX_HINT} and point mano_dir '
                              'at the folder holding them')
    side = _side_from_name(path) if side is None else side
    content = _read_npz(path) if path.suffix == '.npz' else _read_pickle(path)
    missing = [key for key in FILE_KEYS if key not in content]
    if missing:
        raise CheckpointError(f'{path}: missing MANO keys {missing}; {_FIX_HINT}')
    fields = {field: _to_array(content[key], key, str(path)) for key, field in FILE_KEYS.items()}
    return ManoData(side=side, source=str(path), **fields)


def save_mano_npz(data: ManoData, path: str | Path) -> None:
    """Save MANO arrays as a chumpy-free ``.npz`` with the official keys (keep it private)."""
    arrays = {key: getattr(data, field) for key, field in FILE_KEYS.items()}
    np.savez(Path(path), **arrays)


def fix_left_shapedirs(left: ManoData, right: ManoData) -> ManoData:
    """Undo the known sign bug of the official left model's shapedirs (smplx issue #48).

    In the official MANO_LEFT.pkl the x components of ``shapedirs`` equal the right model's instead
    of being mirrored, so equal betas give differently shaped hands. When that is detected, the
    left x components are negated; otherwise ``left`` is returned unchanged.

    Raises:
        CheckpointError: if ``left`` is not a left model or ``right`` not a right one.

    """
    if left.side != LEFT or right.side != RIGHT:
        raise CheckpointError(f'fix_left_shapedirs needs a left and a right model, got sides '
                              f'{left.side} ({left.source}) and {right.side} ({right.source})')
    difference = np.abs(left.shapedirs[:, 0] - right.shapedirs[:, 0]).sum()
    if difference >= SHAPEDIRS_BUG_TOLERANCE:
        return left
    logger.info('%s: negating shapedirs x (official left-model bug)', left.source)
    shapedirs = left.shapedirs.copy()
    shapedirs[:, 0] *= -1.0
    return dataclasses.replace(left, shapedirs=shapedirs)
