"""Models that ship inside the package (``models/<name>/``, installed under share/).

``engine.model.checkpoint`` (and every ``--checkpoint``) accepts a checkpoint directory or the
name of a bundled model; ``resolve_checkpoint`` turns either into a directory. A bundled model
is an ordinary checkpoint directory (``model/io/checkpoint.py``) plus, optionally, the
training set's mean articulation (``MEAN_POSE_FILE``, for the evaluation's mean-pose baseline)
and its model card.
"""

from pathlib import Path
from typing import Final

from infinihand_ros.core.config import package_share_dir
from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import ConfigError

#: The package folder holding the bundled models.
MODELS_DIR: Final = 'models'
#: The default model of the engine, the demo, the node and the converter.
DEFAULT_MODEL: Final = 'tiny_synthetic'
#: File of a checkpoint directory with the training set's mean articulation (right hand).
MEAN_POSE_FILE: Final = 'mean_pose.json'


def bundled_models() -> list[str]:
    """Return the names of the bundled models (empty when the package ships none)."""
    try:
        root = package_share_dir(MODELS_DIR)
    except ConfigError:
        return []
    return sorted(path.name for path in root.iterdir() if path.is_dir())


def resolve_checkpoint(value: str) -> Path:
    """Return the checkpoint directory of ``value``: an existing directory or a bundled name.

    Raises:
        CheckpointError: naming the value and the bundled models when it is neither.

    """
    path = Path(value).expanduser()
    if path.is_dir():
        return path
    names = bundled_models()
    if value in names:
        return package_share_dir(MODELS_DIR) / value
    raise CheckpointError(f'checkpoint {value!r}: no such directory and no bundled model of '
                          f'that name (bundled: {names or "none"})')
