"""Per-sequence prediction files: ``<name>.npz`` that anyone can recompute the metrics from.

Arrays (T frames of the sequence's ground truth, side axis [left, right]): ``joints_world``
(T, 2, 21, 3) float64 metres, NaN where no hand; ``hand_valid`` (T, 2) bool; ``T_world_cam``
(T, 4, 4) float64, NaN where the engine gave no result; ``timestamp_ns`` (T,) int64. Written
atomically (a crash never leaves a half file).
"""

import io
from pathlib import Path
from typing import Final

from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.eval.runner import Predictions
import numpy as np

#: The arrays of a prediction file, with their per-frame shapes and dtypes.
ARRAYS: Final = {'joints_world': ((2, NUM_JOINTS, 3), np.float64),
                 'hand_valid': ((2,), np.bool_),
                 'T_world_cam': ((4, 4), np.float64),
                 'timestamp_ns': ((), np.int64)}


def write_predictions(path: str | Path, predictions: Predictions) -> None:
    """Write the prediction file of one sequence to ``path`` (atomically)."""
    buffer = io.BytesIO()
    np.savez(buffer, **{name: np.asarray(getattr(predictions, name), dtype=dtype)
                        for name, (_, dtype) in ARRAYS.items()})
    atomic_write_bytes(path, buffer.getvalue())


def read_predictions(path: str | Path) -> dict[str, np.ndarray]:
    """Read a prediction file back, checking every array's shape and dtype.

    Raises:
        InputError: naming the file and the array that is missing or malformed.

    """
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError) as exc:
        raise InputError(f'{path}: not a readable prediction file ({exc})') from exc
    frames = None
    for name, (shape, dtype) in ARRAYS.items():
        if name not in arrays:
            raise InputError(f'{path}: no {name!r} array')
        array = arrays[name]
        frames = len(array) if frames is None else frames
        if array.dtype != dtype or array.shape != (frames, *shape):
            expected = ', '.join(map(str, (frames, *shape)))
            raise InputError(f'{path}: {name} has shape {array.shape} and dtype {array.dtype}; '
                             f'expected ({expected}) {np.dtype(dtype)}')
    return arrays
