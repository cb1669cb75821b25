"""Whole-model checkpoints: a directory with weights and the two branch configs.

Layout: ``model.safetensors`` (every tensor of ``InfiniHandModel`` except the hand models', which
are MANO data when real MANO is used and must never be redistributed), ``geometry.yaml`` (section
``geometry``) and ``hand_branch.yaml`` (section ``hand_branch``), both readable by the ordinary
config loaders. The directory is written atomically. Loading builds the model from the saved
configs, takes the hand models from the caller (the built-in skeletons by default) and loads the
weights with ``load_state_dict_checked``.
"""

from dataclasses import asdict
from pathlib import Path
from typing import Final

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.mano.base import HandModel
from infinihand_ros.model.checkpoint import config_to_yaml
from infinihand_ros.model.checkpoint import load_state_dict_checked
from infinihand_ros.model.checkpoint import LoadReport
from infinihand_ros.model.checkpoint import read_safetensors
from infinihand_ros.model.checkpoint import WEIGHTS_FILE
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.hand.config import CONFIG_SECTION as HAND_SECTION
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import HAND_MODELS_PREFIX
from infinihand_ros.model.infinihand_model import InfiniHandModel
from safetensors.torch import save_file
import torch
import yaml

GEOMETRY_FILE: Final = 'geometry.yaml'
HAND_BRANCH_FILE: Final = 'hand_branch.yaml'
CHECKPOINT_FILES: Final = (WEIGHTS_FILE, GEOMETRY_FILE, HAND_BRANCH_FILE)


def hand_branch_config_to_yaml(config: HandBranchConfig) -> str:
    """Return the YAML text of ``config`` under the ``hand_branch:`` section."""
    return yaml.safe_dump({HAND_SECTION: asdict(config)}, sort_keys=False)


def checkpoint_tensors(model: InfiniHandModel) -> dict[str, torch.Tensor]:
    """Return the CPU tensors a checkpoint holds: the state dict without the hand models'."""
    return {key: value.detach().to('cpu').contiguous()
            for key, value in model.state_dict().items()
            if not key.startswith(HAND_MODELS_PREFIX)}


def save_infinihand_checkpoint(model: InfiniHandModel, directory: str | Path,
                               overwrite: bool = False) -> Path:
    """Write ``model``'s weights (no hand-model data) and both configs to ``directory``.

    The directory appears only when complete; on error nothing is left and an existing
    directory is untouched.

    Raises:
        InputError: when ``directory`` exists and ``overwrite`` is False.

    """
    directory = Path(directory)
    tensors = checkpoint_tensors(model)
    with atomic_directory(directory, overwrite=overwrite) as staging:
        staging.mkdir()
        (staging / GEOMETRY_FILE).write_text(config_to_yaml(model.geometry.config),
                                             encoding='utf-8')
        (staging / HAND_BRANCH_FILE).write_text(
            hand_branch_config_to_yaml(model.hand_branch.config), encoding='utf-8')
        save_file(tensors, staging / WEIGHTS_FILE, metadata={'format': 'pt'})
    return directory


def _check_layout(directory: Path) -> None:
    """Raise CheckpointError unless ``directory`` holds every checkpoint file."""
    if not directory.is_dir():
        raise CheckpointError(f'{directory}: no such checkpoint directory; pass a directory '
                              'written by save_infinihand_checkpoint or convert_wilor')
    missing = [name for name in CHECKPOINT_FILES if not (directory / name).is_file()]
    if missing:
        raise CheckpointError(f'{directory}: not an InfiniHand checkpoint, {missing} missing '
                              f'(expected {list(CHECKPOINT_FILES)}); write it again with '
                              'save_infinihand_checkpoint')


def load_infinihand_checkpoint(directory: str | Path,
                               hand_models: tuple[HandModel, HandModel] | None = None,
                               device: str | torch.device = 'cpu'
                               ) -> tuple[InfiniHandModel, LoadReport]:
    """Build the model of ``directory``'s configs and load its weights strictly.

    Args:
        directory: a checkpoint directory (``model.safetensors``, ``geometry.yaml``,
            ``hand_branch.yaml``).
        hand_models: (left, right) hand models, e.g. real MANO from the user's own files; the
            built-in skeletons if None. Their tensors are never in a checkpoint.
        device: device of the returned model.

    Returns:
        The model in eval mode on ``device`` and the load report.

    Raises:
        CheckpointError: for a missing directory or file, an unreadable weights file, any key or
            shape difference, or hand-model tensors in the file.
        ConfigError: for a bad config file.

    """
    directory = Path(directory)
    _check_layout(directory)
    model = build_infinihand_model(load_geometry_config(directory / GEOMETRY_FILE),
                                   load_hand_branch_config(directory / HAND_BRANCH_FILE),
                                   hand_models=hand_models)
    tensors = read_safetensors(directory / WEIGHTS_FILE)
    licensed = [key for key in tensors if key.startswith(HAND_MODELS_PREFIX)]
    if licensed:
        raise CheckpointError(f'{directory / WEIGHTS_FILE}: holds hand-model tensors '
                              f'{licensed[:4]}; checkpoints must not carry MANO data, save it '
                              'again with save_infinihand_checkpoint')
    report = load_state_dict_checked(model, tensors, str(directory),
                                     allow_missing=(HAND_MODELS_PREFIX,))
    return model.to(device).eval(), report
