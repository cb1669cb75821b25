"""Input checks at the edges: shapes, dtypes and finiteness, with errors that name the input."""

from infinihand_ros.core.errors import InputError
import numpy as np


def as_array(value: object, name: str, shape: tuple[int | None, ...],
             dtype: type = np.float64, finite: bool = True) -> np.ndarray:
    """Return ``value`` as an array of ``dtype`` after checking its shape and values.

    Args:
        value: anything ``np.asarray`` accepts.
        name: what the caller calls this input (used in the error message).
        shape: expected shape; ``None`` entries match any size.
        dtype: dtype of the returned array.
        finite: reject NaN and infinite values.

    Raises:
        InputError: naming the input, the shape or values found and what was expected.

    """
    try:
        array = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f'{name}: cannot convert to a {np.dtype(dtype).name} array ({exc})') from exc
    if array.ndim != len(shape) or any(
            want is not None and got != want for got, want in zip(array.shape, shape)):
        want_text = '(' + ', '.join('N' if s is None else str(s) for s in shape) + ')'
        raise InputError(f'{name}: expected shape {want_text}, got {tuple(array.shape)}')
    if finite and np.issubdtype(array.dtype, np.floating) and not np.all(np.isfinite(array)):
        bad = int(np.size(array) - np.count_nonzero(np.isfinite(array)))
        raise InputError(f'{name}: {bad} value(s) are NaN or infinite; pass finite numbers')
    return array
