"""Models that ship inside the package (``models/<name>/``, installed under share/).

``engine.model.checkpoint`` (and every ``--checkpoint``) accepts a checkpoint directory or the
name of a bundled model; ``resolve_checkpoint`` turns either into a directory. A bundled model
is an ordinary checkpoint directory (``model/io/checkpoint.py``) plus, optionally, the
training set's mean articulation (``MEAN_POSE_FILE``, for the evaluation's mean-pose baseline),
its measured hand-depth correction of the metric scale (``SCALE_CALIBRATION_FILE``) and its
model card.
"""

import json
import math
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
#: File of a checkpoint directory with its measured hand-depth correction of the metric scale.
SCALE_CALIBRATION_FILE: Final = 'scale_calibration.json'
#: The correction's key in that file.
CORRECTION_KEY: Final = 'hand_depth_correction'


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


def hand_depth_correction(checkpoint: Path) -> float:
    """Return the checkpoint's measured hand-depth correction (1.0 when it has none).

    A depth head can place hands too far or too near relative to the rest of the scene; the
    metric scale, taken from hands, is then off by that factor. ``SCALE_CALIBRATION_FILE`` holds
    the factor measured on sequences with true depth (``python -m
    infinihand_ros.eval.scale_calibration``).

    Raises:
        CheckpointError: naming the file when it is unreadable or its value is not positive.

    """
    path = Path(checkpoint) / SCALE_CALIBRATION_FILE
    if not path.is_file():
        return 1.0
    try:
        value = float(json.loads(path.read_text())[CORRECTION_KEY])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CheckpointError(f'{path}: unreadable ({exc}); expected JSON with a positive '
                              f'"{CORRECTION_KEY}" (rewrite it with python -m '
                              'infinihand_ros.eval.scale_calibration, or delete it)') from exc
    if not (math.isfinite(value) and value > 0):
        raise CheckpointError(f'{path}: "{CORRECTION_KEY}" must be a positive number, got '
                              f'{value}; rewrite it with python -m '
                              'infinihand_ros.eval.scale_calibration, or delete it')
    return value
