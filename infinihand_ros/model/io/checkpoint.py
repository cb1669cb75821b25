"""The one checkpoint format, and checked loading of state dicts.

A checkpoint is a directory:

- ``model.safetensors``: tensors under ``InfiniHandModel``'s key names (``geometry.*``,
  ``hand_branch.*``), never the hand models' (MANO data is licensed; the caller's hand models
  provide those). It may hold the whole model or a part of it: the LingBot-Map / VGGT
  converter writes ``geometry.aggregator``, ``geometry.camera_head`` and ``geometry.depth_head``,
  the WiLoR converter ``hand_branch.backbone``, training the whole model.
- ``geometry.yaml`` (section ``geometry``) when it holds ``geometry.*`` tensors and
  ``hand_branch.yaml`` (section ``hand_branch``) when it holds ``hand_branch.*`` tensors: the
  resolved configs, complete (loading refuses a missing field), readable by the usual loaders.

Parts compose: ``model/io/compose.py`` loads any set of them into one model. Writing is atomic.
``load_state_dict_checked`` compares names and shapes first and raises ``CheckpointError``
listing the missing, unexpected and shape-mismatched keys; keys the caller allows to be missing
are counted apart and left out of that list.
"""

from collections.abc import Mapping
from collections.abc import Sequence
from dataclasses import asdict
from dataclasses import dataclass
from dataclasses import field
import logging
from pathlib import Path
from typing import Final

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import honour_umask
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.config import GEOMETRY_SECTION
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.hand.config import CONFIG_SECTION as HAND_SECTION
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.infinihand_model import GEOMETRY_PREFIX
from infinihand_ros.model.infinihand_model import HAND_BRANCH_PREFIX
from infinihand_ros.model.infinihand_model import HAND_MODELS_PREFIX
from infinihand_ros.model.infinihand_model import InfiniHandModel
from safetensors import safe_open
from safetensors import SafetensorError
from safetensors.torch import save_file
import torch
from torch import nn
import yaml

logger = logging.getLogger(__name__)

WEIGHTS_FILE: Final = 'model.safetensors'
GEOMETRY_FILE: Final = 'geometry.yaml'
HAND_BRANCH_FILE: Final = 'hand_branch.yaml'
#: safetensors metadata key naming where the weights came from (e.g. ``lingbot-map: x.pt``).
SOURCE_METADATA: Final = 'source'
_LIST_LIMIT: Final = 10


@dataclass(frozen=True)
class LoadReport:
    """Differences between a module's state dict and a checkpoint's.

    Attributes:
        source: name of the checkpoint (path or description) for messages.
        missing: keys the module has and the checkpoint lacks, not allowed to be missing.
        unexpected: keys the checkpoint has and the module lacks.
        mismatched: (key, module shape, checkpoint shape) for keys present in both.
        matched: number of keys present in both with equal shapes.
        allowed_missing: keys the checkpoint lacks under the caller's allowed prefixes; they
            keep their values and are not listed by ``describe``.

    """

    source: str
    missing: tuple[str, ...]
    unexpected: tuple[str, ...]
    mismatched: tuple[tuple[str, tuple[int, ...], tuple[int, ...]], ...]
    matched: int
    allowed_missing: tuple[str, ...] = ()

    @property
    def exact(self) -> bool:
        """Return True when nothing is missing, unexpected or of another shape."""
        return not (self.missing or self.unexpected or self.mismatched or self.allowed_missing)

    @property
    def ok(self) -> bool:
        """Return True when the checkpoint can be loaded (only allowed keys are missing)."""
        return not (self.missing or self.unexpected or self.mismatched)

    def describe(self) -> str:
        """Return a readable multi-line summary (first keys of each kind)."""
        allowed = f', {len(self.allowed_missing)} allowed missing' if self.allowed_missing else ''
        lines = [f'{self.source}: {self.matched} keys match, {len(self.missing)} missing, '
                 f'{len(self.unexpected)} unexpected, {len(self.mismatched)} shape-mismatched'
                 f'{allowed}']
        lines += describe_keys('missing', self.missing)
        lines += describe_keys('unexpected', self.unexpected)
        for key, ours, theirs in self.mismatched[:_LIST_LIMIT]:
            lines.append(f'  shape of {key}: model {list(ours)}, checkpoint {list(theirs)}')
        return '\n'.join(lines)


def describe_keys(title: str, keys: Sequence[str]) -> list[str]:
    """Return one indented line listing the first keys of ``keys`` (none when empty)."""
    if not keys:
        return []
    more = f' (+{len(keys) - _LIST_LIMIT} more)' if len(keys) > _LIST_LIMIT else ''
    return [f'  {title}: {", ".join(keys[:_LIST_LIMIT])}{more}']


def compare_state_dict(module: nn.Module, state_dict: Mapping[str, torch.Tensor], source: str,
                       allow_missing: Sequence[str] = ()) -> LoadReport:
    """Return the ``LoadReport`` of loading ``state_dict`` into ``module`` (nothing is loaded).

    Args:
        module: the receiving module (may live on the meta device: only shapes are read).
        state_dict: tensors by key.
        source: checkpoint name used in messages.
        allow_missing: key prefixes the checkpoint may lack.

    """
    expected = {key: tuple(value.shape) for key, value in module.state_dict().items()}
    given = {key: tuple(value.shape) for key, value in state_dict.items()}
    absent = [key for key in expected if key not in given]
    allowed = tuple(key for key in absent if key.startswith(tuple(allow_missing)))
    return LoadReport(source,
                      missing=tuple(key for key in absent if key not in allowed),
                      unexpected=tuple(key for key in given if key not in expected),
                      mismatched=tuple((key, expected[key], given[key]) for key in expected
                                       if key in given and expected[key] != given[key]),
                      matched=sum(1 for key in expected
                                  if key in given and expected[key] == given[key]),
                      allowed_missing=allowed)


def load_state_dict_checked(module: nn.Module, state_dict: Mapping[str, torch.Tensor],
                            source: str, allow_missing: Sequence[str] = ()) -> LoadReport:
    """Load ``state_dict`` into ``module`` after checking every name and shape.

    Args:
        module: the receiving module.
        state_dict: tensors by key (e.g. from ``read_safetensors`` or a converter).
        source: checkpoint name used in messages.
        allow_missing: key prefixes the checkpoint may lack (those weights keep their values).

    Returns:
        The report (anything missing is in ``allowed_missing``).

    Raises:
        CheckpointError: for any unexpected key, shape mismatch or missing key outside
            ``allow_missing``; nothing is loaded then.

    """
    report = compare_state_dict(module, state_dict, source, allow_missing)
    if not report.ok:
        raise CheckpointError(f'{report.describe()}\nThe checkpoint does not fit this model; '
                              'check the configuration file or convert the checkpoint first.')
    # Every absent key was checked above against the caller's allow-list, so strict=False only
    # skips those.
    module.load_state_dict(dict(state_dict), strict=not report.allowed_missing)
    return report


def read_safetensors(path: str | Path) -> dict[str, torch.Tensor]:
    """Return the tensors of a safetensors file (on the CPU).

    Raises:
        CheckpointError: when the file is missing or not a safetensors file.

    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f'{path}: no such weights file; pass a checkpoint directory made '
                              'by save_infinihand_checkpoint or a converter')
    try:
        with safe_open(path, framework='pt') as handle:
            return {key: handle.get_tensor(key) for key in handle.keys()}
    except (SafetensorError, OSError) as exc:
        raise CheckpointError(f'{path}: not a readable safetensors file ({exc})') from exc


def read_metadata(path: str | Path) -> dict[str, str]:
    """Return the string metadata of a safetensors file (empty when it has none).

    Raises:
        CheckpointError: when the file is not a readable safetensors file.

    """
    try:
        with safe_open(Path(path), framework='pt') as handle:
            return dict(handle.metadata() or {})
    except (SafetensorError, OSError) as exc:
        raise CheckpointError(f'{path}: not a readable safetensors file ({exc})') from exc


def _plain(value: object) -> object:
    """Return ``value`` with tuples as lists, for YAML."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, (tuple, list)):
        return [_plain(item) for item in value]
    return value


def config_to_yaml(config: GeometryConfig) -> str:
    """Return the complete YAML text of ``config`` under the ``geometry:`` section."""
    return yaml.safe_dump({GEOMETRY_SECTION: _plain(asdict(config))}, sort_keys=False)


def hand_branch_config_to_yaml(config: HandBranchConfig) -> str:
    """Return the complete YAML text of ``config`` under the ``hand_branch:`` section."""
    return yaml.safe_dump({HAND_SECTION: _plain(asdict(config))}, sort_keys=False)


@dataclass(frozen=True)
class CheckpointContents:
    """What one checkpoint directory holds.

    Attributes:
        path: the directory.
        tensors: every tensor by whole-model key.
        geometry_config: from ``geometry.yaml``, when the directory has geometry tensors.
        hand_config: from ``hand_branch.yaml``, when it has hand-branch tensors.
        metadata: the weights file's string metadata (e.g. ``source``).

    """

    path: Path
    tensors: dict[str, torch.Tensor]
    geometry_config: GeometryConfig | None
    hand_config: HandBranchConfig | None
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def source(self) -> str:
        """Return the directory, and where its weights came from when recorded."""
        origin = self.metadata.get(SOURCE_METADATA)
        return f'{self.path} ({origin})' if origin else str(self.path)


def _portable(tensors: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Return CPU tensors that each own their storage (safetensors refuses shared memory)."""
    out = {}
    for key, tensor in tensors.items():
        tensor = tensor.detach().to('cpu').contiguous()
        if tensor.untyped_storage().nbytes() != tensor.numel() * tensor.element_size():
            tensor = tensor.clone()
        out[key] = tensor
    return out


def write_checkpoint(directory: str | Path, tensors: Mapping[str, torch.Tensor],
                     geometry_config: GeometryConfig | None = None,
                     hand_config: HandBranchConfig | None = None, source: str | None = None,
                     overwrite: bool = False,
                     extra_files: Mapping[str, bytes] | None = None) -> Path:
    """Write a checkpoint (whole model or a part) to ``directory`` atomically.

    Args:
        directory: the checkpoint directory to create.
        tensors: tensors under whole-model keys (``geometry.*``, ``hand_branch.*``).
        geometry_config: required when there are ``geometry.*`` tensors (and only then).
        hand_config: required when there are ``hand_branch.*`` tensors (and only then).
        source: where the weights came from, recorded in the weights file's metadata.
        overwrite: replace an existing directory.
        extra_files: more files of the directory (name -> content), e.g. a model card.

    Raises:
        CheckpointError: for keys outside the two branches, hand-model tensors, or a config
            that is missing or has no tensors.
        InputError: when ``directory`` exists and ``overwrite`` is False.

    """
    _check_part_keys(tensors, str(directory), geometry_config is not None,
                     hand_config is not None)
    metadata = {'format': 'pt', **({SOURCE_METADATA: source} if source else {})}
    portable = _portable(tensors)
    directory = Path(directory)
    with atomic_directory(directory, overwrite=overwrite) as staging:
        staging.mkdir()
        if geometry_config is not None:
            (staging / GEOMETRY_FILE).write_text(config_to_yaml(geometry_config),
                                                 encoding='utf-8')
        if hand_config is not None:
            (staging / HAND_BRANCH_FILE).write_text(hand_branch_config_to_yaml(hand_config),
                                                    encoding='utf-8')
        save_file(portable, staging / WEIGHTS_FILE, metadata=metadata)
        honour_umask(staging / WEIGHTS_FILE)
        for name, content in (extra_files or {}).items():
            (staging / name).write_bytes(content)
    return directory


def _check_part_keys(tensors: Mapping[str, object], where: str, has_geometry_config: bool,
                     has_hand_config: bool) -> None:
    """Raise CheckpointError unless the keys and the configs of a checkpoint belong together."""
    outside = [key for key in tensors if not key.startswith((GEOMETRY_PREFIX, HAND_BRANCH_PREFIX))]
    licensed = [key for key in tensors if key.startswith(HAND_MODELS_PREFIX)]
    if outside or licensed:
        raise CheckpointError(f'{where}: keys outside geometry.* / hand_branch.* {outside[:4]} '
                              f'or hand-model tensors {licensed[:4]}; checkpoints hold '
                              'whole-model keys and never MANO data')
    for prefix, name, has_config in ((GEOMETRY_PREFIX, GEOMETRY_FILE, has_geometry_config),
                                     (HAND_BRANCH_PREFIX, HAND_BRANCH_FILE, has_hand_config)):
        has_tensors = any(key.startswith(prefix) for key in tensors)
        if has_tensors != has_config:
            state = 'without' if has_tensors else 'with'
            raise CheckpointError(f'{where}: {prefix}* tensors {state} {name}; a checkpoint '
                                  'holds the config of exactly the branches it has weights for')


def read_checkpoint(directory: str | Path) -> CheckpointContents:
    """Read a checkpoint directory: tensors, the configs of its branches and the metadata.

    Raises:
        CheckpointError: for a missing directory or weights file, an unreadable weights file,
            hand-model tensors, or configs that do not match the tensors.
        ConfigError: for a bad or incomplete config file.

    """
    directory = Path(directory)
    if not directory.is_dir():
        raise CheckpointError(f'{directory}: no such checkpoint directory; pass a directory '
                              'written by save_infinihand_checkpoint or a converter')
    weights = directory / WEIGHTS_FILE
    if not weights.is_file():
        raise CheckpointError(f'{directory}: not a checkpoint, {WEIGHTS_FILE} is missing; write '
                              'it again with save_infinihand_checkpoint or a converter')
    tensors = read_safetensors(weights)
    geometry_path, hand_path = directory / GEOMETRY_FILE, directory / HAND_BRANCH_FILE
    _check_part_keys(tensors, str(weights), geometry_path.is_file(), hand_path.is_file())
    geometry = (load_geometry_config(geometry_path, require_complete=True)
                if geometry_path.is_file() else None)
    hand = (load_config(hand_path, HAND_SECTION, HandBranchConfig, require_complete=True)
            if hand_path.is_file() else None)
    return CheckpointContents(directory, tensors, geometry, hand, read_metadata(weights))


def checkpoint_tensors(model: InfiniHandModel) -> dict[str, torch.Tensor]:
    """Return the tensors a checkpoint of ``model`` holds: all but the hand models'."""
    return {key: value for key, value in model.state_dict().items()
            if not key.startswith(HAND_MODELS_PREFIX)}


def save_infinihand_checkpoint(model: InfiniHandModel, directory: str | Path,
                               overwrite: bool = False) -> Path:
    """Write ``model``'s weights (no hand-model data) and both configs to ``directory``.

    The directory appears only when complete; on error nothing is left and an existing
    directory is untouched.

    Raises:
        InputError: when ``directory`` exists and ``overwrite`` is False.

    """
    return write_checkpoint(directory, checkpoint_tensors(model), model.geometry.config,
                            model.hand_branch.config, overwrite=overwrite)
