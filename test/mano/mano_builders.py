"""Builders of fake MANO model files: random but well-formed arrays in the official layout.

The official pickles hold some arrays as chumpy ``Ch`` objects and the joint regressor as a
scipy.sparse matrix. ``write_fake_mano_pickle`` reproduces that: it wraps values in a class named
``chumpy.ch.Ch`` that exists in ``sys.modules`` only while dumping, so loading the file proves that
chumpy is not needed.
"""

from collections.abc import Iterator
import contextlib
from pathlib import Path
import pickle
import sys
import types

from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.mano.mano_file import NUM_FACES
from infinihand_ros.mano.mano_file import NUM_POSE_FEATURES
from infinihand_ros.mano.mano_file import NUM_POSE_PARAMS
from infinihand_ros.mano.mano_file import NUM_VERTICES
import numpy as np
import scipy.sparse

#: kintree_table stores the root's parent as uint32 max in the official files.
ROOT_PARENT_UINT32 = 2 ** 32 - 1
#: Vertices averaged by each joint of the fake regressor.
VERTICES_PER_JOINT = 12
#: Spread of the fake template (m), about a hand's size.
TEMPLATE_SCALE_M = 0.04
#: Magnitude of the fake shape and pose blend shapes (m per unit).
BLEND_SCALE_M = 0.002
#: Keys the official files also hold that the loader does not need.
UNUSED_KEYS = ('bs_style', 'bs_type', 'J', 'hands_coeffs')
#: Official keys wrapped in a fake chumpy object.
CHUMPY_KEYS = ('v_template', 'shapedirs', 'posedirs', 'J')


def fake_mano_arrays(rng: np.random.Generator) -> dict[str, object]:
    """Return official-layout MANO arrays (J_regressor as scipy.sparse.csc_matrix)."""
    regressor = np.zeros((NUM_MANO_JOINTS, NUM_VERTICES))
    for joint in range(NUM_MANO_JOINTS):
        ids = rng.choice(NUM_VERTICES, size=VERTICES_PER_JOINT, replace=False)
        regressor[joint, ids] = rng.dirichlet(np.ones(VERTICES_PER_JOINT))
    kintree = np.array([[ROOT_PARENT_UINT32, *MANO_PARENTS[1:]], range(NUM_MANO_JOINTS)],
                       dtype=np.uint32)
    v_template = rng.normal(scale=TEMPLATE_SCALE_M, size=(NUM_VERTICES, 3))
    return {
        'v_template': v_template,
        'shapedirs': rng.normal(scale=BLEND_SCALE_M, size=(NUM_VERTICES, 3, NUM_BETAS)),
        'posedirs': rng.normal(scale=BLEND_SCALE_M, size=(NUM_VERTICES, 3, NUM_POSE_FEATURES)),
        'J_regressor': scipy.sparse.csc_matrix(regressor),
        'weights': rng.dirichlet(np.ones(NUM_MANO_JOINTS), size=NUM_VERTICES),
        'kintree_table': kintree,
        'f': rng.integers(0, NUM_VERTICES, size=(NUM_FACES, 3)).astype(np.uint32),
        'hands_components': rng.normal(size=(NUM_POSE_PARAMS, NUM_POSE_PARAMS)),
        'hands_mean': rng.normal(scale=0.1, size=NUM_POSE_PARAMS),
        'bs_style': 'lbs',
        'bs_type': 'lrotmin',
        'J': regressor @ v_template,
        'hands_coeffs': rng.normal(size=(4, NUM_POSE_PARAMS)),
    }


@contextlib.contextmanager
def fake_chumpy() -> Iterator[type]:
    """Register modules ``chumpy`` / ``chumpy.ch`` with a class ``Ch`` while the block runs."""
    package, module = types.ModuleType('chumpy'), types.ModuleType('chumpy.ch')

    class Ch:
        """Stand-in for chumpy's Ch: pickles its value under 'x' in its __dict__, like chumpy."""

        def __init__(self, value: np.ndarray) -> None:
            self.x = value
            self._dirty_vars = set()
            self._itr = None

    Ch.__module__, Ch.__qualname__ = 'chumpy.ch', 'Ch'
    module.Ch = Ch
    package.ch = module
    sys.modules['chumpy'], sys.modules['chumpy.ch'] = package, module
    try:
        yield Ch
    finally:
        del sys.modules['chumpy'], sys.modules['chumpy.ch']


def write_fake_mano_pickle(path: Path, arrays: dict[str, object],
                           chumpy_keys: tuple[str, ...] = CHUMPY_KEYS) -> Path:
    """Pickle ``arrays`` (protocol 2, like the official files) with chumpy-wrapped values."""
    with fake_chumpy() as ch_class:
        content = {key: ch_class(value) if key in chumpy_keys else value
                   for key, value in arrays.items()}
        path.write_bytes(pickle.dumps(content, protocol=2))
    return path
