"""Training checkpoints: the model, everything needed to resume bit-for-bit, and the config.

A checkpoint is a directory ``<output>/checkpoints/step_<step>`` (``final`` for the end of the
schedule), written atomically (it appears complete or not at all)::

    model/              the model checkpoint (model/io/checkpoint.py: loads anywhere)
    train_state.pt      step, optimizer, scheduler, the data position and every process's
                        torch / CUDA / numpy / Python / box-sampling random states
    train_config.yaml   the resolved TrainConfig (train_config.train_config_to_yaml)

``train_state.pt`` holds plain data and tensors only, so it loads with ``weights_only=True``.
"""

from dataclasses import dataclass
import io
from pathlib import Path
import random
import re
from typing import Any, Final

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.io.checkpoint import save_infinihand_checkpoint
from infinihand_ros.train.train_config import train_config_to_yaml
from infinihand_ros.train.train_config import TrainConfig
import numpy as np
import torch

CHECKPOINTS_DIR: Final = 'checkpoints'
MODEL_DIR: Final = 'model'
STATE_FILE: Final = 'train_state.pt'
CONFIG_FILE: Final = 'train_config.yaml'
FINAL_NAME: Final = 'final'
_STEP_NAME: Final = re.compile(r'step_(\d+)')


def checkpoint_name(step: int, final: bool) -> str:
    """Return the directory name of the checkpoint after ``step`` optimizer steps."""
    return FINAL_NAME if final else f'step_{step:07d}'


def capture_rng(step_generator: torch.Generator) -> dict[str, Any]:
    """Return this process's random states as plain data and tensors."""
    kind, keys, position, has_gauss, gauss = np.random.get_state()
    return {
        'torch': torch.get_rng_state(),
        'cuda': torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
        'numpy': (kind, torch.from_numpy(keys.astype(np.int64)), int(position), int(has_gauss),
                  float(gauss)),
        'python': random.getstate(),
        'box': step_generator.get_state(),  # key kept: checkpoints written before the rename
    }


def restore_rng(state: dict[str, Any], step_generator: torch.Generator) -> None:
    """Restore the random states ``capture_rng`` returned."""
    torch.set_rng_state(state['torch'])
    if state['cuda'] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state['cuda'])
    kind, keys, position, has_gauss, gauss = state['numpy']
    np.random.set_state((kind, keys.numpy().astype(np.uint32), position, has_gauss, gauss))
    version, internal, gauss_next = state['python']
    random.setstate((version, tuple(internal), gauss_next))
    step_generator.set_state(state['box'])


@dataclass(frozen=True)
class ResumePoint:
    """What a checkpoint gives a resumed run.

    Attributes:
        directory: the checkpoint directory.
        step: optimizer steps done.
        state: the contents of ``train_state.pt``.

    """

    directory: Path
    step: int
    state: dict[str, Any]


def save_training_checkpoint(directory: str | Path, model: InfiniHandModel,
                             optimizer: torch.optim.Optimizer,
                             scheduler: torch.optim.lr_scheduler.LRScheduler,
                             config: TrainConfig, step: int, rng_states: list[dict[str, Any]],
                             data_position: tuple[int, int]) -> Path:
    """Write a checkpoint directory atomically (replacing one of the same name).

    Args:
        directory: the checkpoint directory.
        model: the model (not a DDP wrapper).
        optimizer: its optimizer.
        scheduler: its schedule.
        config: the resolved run config.
        step: optimizer steps done.
        rng_states: ``capture_rng`` of every process, by rank.
        data_position: (epoch, batch) the next step reads.

    """
    state = {'step': step, 'optimizer': optimizer.state_dict(),
             'scheduler': scheduler.state_dict(), 'rng': rng_states,
             'data_position': tuple(data_position)}
    buffer = io.BytesIO()
    torch.save(state, buffer)
    directory = Path(directory)
    with atomic_directory(directory, overwrite=True) as staging:
        staging.mkdir()
        save_infinihand_checkpoint(model, staging / MODEL_DIR)
        (staging / STATE_FILE).write_bytes(buffer.getvalue())
        (staging / CONFIG_FILE).write_text(train_config_to_yaml(config), encoding='utf-8')
    return directory


def _checkpoint_step(path: Path) -> int | None:
    """Return the step in a ``step_<n>`` name, None for other names."""
    match = _STEP_NAME.fullmatch(path.name)
    return int(match.group(1)) if match else None


def find_checkpoint(path: str | Path) -> Path:
    """Return the checkpoint ``path`` names: itself, or the newest in an output directory.

    Raises:
        CheckpointError: when ``path`` is neither a checkpoint nor holds one.

    """
    path = Path(path)
    if (path / STATE_FILE).is_file():
        return path
    folder = path / CHECKPOINTS_DIR
    candidates = [child for child in folder.iterdir() if (child / STATE_FILE).is_file()] \
        if folder.is_dir() else []
    if not candidates:
        raise CheckpointError(f'--resume {path}: neither a training checkpoint (no '
                              f'{STATE_FILE}) nor an output directory with {CHECKPOINTS_DIR}/; '
                              'pass what train --output wrote')
    final = [child for child in candidates if child.name == FINAL_NAME]
    if final:
        return final[0]
    numbered = [child for child in candidates if _checkpoint_step(child) is not None]
    if not numbered:
        raise CheckpointError(f'--resume {path}: no step_<n> checkpoint in {folder}')
    return max(numbered, key=lambda child: _checkpoint_step(child))


def read_resume_point(path: str | Path) -> ResumePoint:
    """Read the training state of a checkpoint (``find_checkpoint`` resolves ``path``).

    Raises:
        CheckpointError: for a missing or unreadable state file.

    """
    directory = find_checkpoint(path)
    try:
        state = torch.load(directory / STATE_FILE, map_location='cpu', weights_only=True)
    except (OSError, RuntimeError, ValueError) as exc:
        raise CheckpointError(f'{directory / STATE_FILE}: unreadable training state ({exc}); '
                              'resume from an earlier checkpoint') from exc
    return ResumePoint(directory, int(state['step']), state)
