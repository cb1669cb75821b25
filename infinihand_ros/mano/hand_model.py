"""The hand-model entry point: interface, configuration and factory.

``build_hand_model(config, side)`` returns the built-in skeleton (default, no files needed) or real
MANO when ``config.kind == 'mano'`` and ``config.mano_dir`` holds the official files
(``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl``, or ``.npz`` conversions of them). Both implement
``HandModel``: ``forward(global_orient, hand_pose, betas, transl) -> HandModelOutput``.
"""

from dataclasses import dataclass
import logging
from pathlib import Path
from typing import Final

from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import side_name
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.base import HandModelOutput
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.builtin import canonical_joints
from infinihand_ros.mano.mano_file import fix_left_shapedirs
from infinihand_ros.mano.mano_file import load_mano_data
from infinihand_ros.mano.mano_file import MANO_URL
from infinihand_ros.mano.mano_layer import ManoHandModel

__all__ = ['HandModel', 'HandModelOutput', 'HandModelConfig', 'load_hand_model_config',
           'build_hand_model', 'canonical_joints', 'HAND_MODEL_KINDS']

logger = logging.getLogger(__name__)

#: Accepted values of ``HandModelConfig.kind``.
HAND_MODEL_KINDS: Final = ('builtin', 'mano')
#: Top-level key of a YAML file holding only a hand-model section (the engine's is nested).
CONFIG_SECTION: Final = 'hand_model'
#: Extensions tried, in order, for ``MANO_{LEFT,RIGHT}`` inside ``mano_dir``.
MANO_FILE_SUFFIXES: Final = ('.pkl', '.npz')


@dataclass(frozen=True)
class HandModelConfig:
    """Which hand model to use.

    Attributes:
        kind: 'builtin' (default: our anthropometric skeleton, no files) or 'mano' (real MANO).
        mano_dir: folder holding MANO_RIGHT.pkl / MANO_LEFT.pkl (or .npz); required for 'mano'.

    """

    kind: str = 'builtin'
    mano_dir: str = ''

    def __post_init__(self) -> None:
        """Reject wrong types, unknown kinds and a missing MANO folder (ConfigError)."""
        for name in ('kind', 'mano_dir'):
            value = getattr(self, name)
            if not isinstance(value, str):
                raise ConfigError(f'hand_model.{name}: expected a string, got '
                                  f'{type(value).__name__} {value!r}')
        if self.kind not in HAND_MODEL_KINDS:
            raise ConfigError(f'hand_model.kind: unknown kind {self.kind!r}; use one of '
                              f'{list(HAND_MODEL_KINDS)}')
        if self.kind == 'mano' and (not self.mano_dir
                                    or not Path(self.mano_dir).expanduser().is_dir()):
            raise ConfigError(
                f'hand_model.mano_dir: kind "mano" needs the folder holding MANO_RIGHT.pkl and '
                f'MANO_LEFT.pkl, got {self.mano_dir!r} (not an existing folder); register and '
                f'download MANO at {MANO_URL}, then set mano_dir (or use kind "builtin")')


def load_hand_model_config(path: str | Path) -> HandModelConfig:
    """Read the ``hand_model`` section (``kind``, ``mano_dir``) of a YAML file.

    Raises:
        ConfigError: for a missing or unparsable file, unknown keys or wrong types.

    """
    return load_config(path, CONFIG_SECTION, HandModelConfig)


def _mano_path(mano_dir: Path, side: int) -> Path:
    """Return ``mano_dir/MANO_{SIDE}.pkl`` (or .npz); CheckpointError if neither exists."""
    stem = f'MANO_{side_name(side).upper()}'
    for suffix in MANO_FILE_SUFFIXES:
        candidate = mano_dir / (stem + suffix)
        if candidate.is_file():
            return candidate
    raise CheckpointError(f'{mano_dir / (stem + MANO_FILE_SUFFIXES[0])}: MANO file not found; '
                          f'download it from {MANO_URL} into mano_dir (or use kind "builtin")')


def build_hand_model(config: HandModelConfig, side: int) -> HandModel:
    """Build the configured hand model for one side (0 left, 1 right).

    For real MANO the left model gets the official shapedirs fix when MANO_RIGHT is also present.

    Raises:
        ValueError: for a side other than 0 or 1.
        CheckpointError: if a MANO file is missing or malformed.

    """
    side_name(side)
    if config.kind == 'builtin':
        return BuiltinHandModel(side)
    mano_dir = Path(config.mano_dir).expanduser()
    data = load_mano_data(_mano_path(mano_dir, side), side=side)
    if side == LEFT:
        try:
            right = load_mano_data(_mano_path(mano_dir, RIGHT), side=RIGHT)
        except CheckpointError as exc:
            logger.warning('left MANO shapedirs not checked against the right model: %s', exc)
        else:
            data = fix_left_shapedirs(data, right)
    return ManoHandModel(data)
