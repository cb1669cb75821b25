"""Reading upstream pickle checkpoints (``.pt`` / ``.ckpt``) safely, for the converters.

Files are read only when the user names them, with ``torch.load(weights_only=True)``: tensors
and plain containers, never arbitrary objects.
"""

from collections.abc import Mapping
from pathlib import Path
import pickle
from typing import Final

from infinihand_ros.core.errors import CheckpointError
import torch

#: LingBot-Map's wrapper key of the state dict, and DataParallel's key prefix.
WRAPPER_KEY: Final = 'model'
PARALLEL_PREFIX: Final = 'module.'


def read_torch_checkpoint(path: str | Path, wrapper_key: str = WRAPPER_KEY,
                          what: str = 'checkpoint', hint: str = 'pass the model state dict'
                          ) -> dict[str, torch.Tensor]:
    """Return the tensors of a pickle checkpoint, unwrapped and without ``module.`` prefixes.

    Args:
        path: the ``.pt`` / ``.ckpt`` file the user named.
        wrapper_key: the state dict may sit under this key (``"model"``; Lightning:
            ``"state_dict"``).
        what: what the file is, for error messages.
        hint: what to do when the file holds something else.

    Raises:
        CheckpointError: when the file is missing, not loadable with ``weights_only=True``, or
            holds anything but a (possibly wrapped) mapping of tensors.

    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f'{path}: no such {what} file')
    try:
        content = torch.load(path, map_location='cpu', weights_only=True)
    except (OSError, RuntimeError, pickle.UnpicklingError, EOFError) as exc:
        raise CheckpointError(f'{path}: cannot be read as a weights-only torch checkpoint '
                              f'({exc}); {hint}') from exc
    if isinstance(content, Mapping) and isinstance(content.get(wrapper_key), Mapping):
        content = content[wrapper_key]
    if not isinstance(content, Mapping):
        raise CheckpointError(f'{path}: expected a state dict, got {type(content).__name__}; '
                              f'{hint}')
    bad = [key for key, value in content.items() if not isinstance(value, torch.Tensor)]
    if bad:
        raise CheckpointError(f'{path}: entries that are not tensors: {bad[:5]}; {hint}')
    return {key.removeprefix(PARALLEL_PREFIX): value for key, value in content.items()}
