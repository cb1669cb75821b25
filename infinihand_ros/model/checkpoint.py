"""Checkpoint I/O: our checkpoints are a directory with ``model.safetensors`` and ``config.yaml``.

Every load is checked: ``load_state_dict_checked`` compares names and shapes first and raises
``CheckpointError`` listing the missing, unexpected and shape-mismatched keys. Missing keys are
accepted only under prefixes the caller names (e.g. a fresh ``mask_head.`` when converting
LingBot-Map weights). Other modules (e.g. the hand branch's converters) reuse it.
"""

from collections.abc import Mapping
from collections.abc import Sequence
from dataclasses import asdict
from dataclasses import dataclass
import logging
from pathlib import Path

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.config import GEOMETRY_SECTION
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.geometry_model import GeometryModel
from safetensors import SafetensorError
from safetensors.torch import load_file
from safetensors.torch import save_file
import torch
from torch import nn
import yaml

logger = logging.getLogger(__name__)

WEIGHTS_FILE = 'model.safetensors'
CONFIG_FILE = 'config.yaml'
_LIST_LIMIT = 10


@dataclass(frozen=True)
class LoadReport:
    """Differences between a module's state dict and a checkpoint's.

    Attributes:
        source: name of the checkpoint (path or description) for messages.
        missing: keys the module has and the checkpoint lacks.
        unexpected: keys the checkpoint has and the module lacks.
        mismatched: (key, module shape, checkpoint shape) for keys present in both.
        matched: number of keys present in both with equal shapes.

    """

    source: str
    missing: tuple[str, ...]
    unexpected: tuple[str, ...]
    mismatched: tuple[tuple[str, tuple[int, ...], tuple[int, ...]], ...]
    matched: int

    @property
    def exact(self) -> bool:
        """Return True when names and shapes agree completely."""
        return not (self.missing or self.unexpected or self.mismatched)

    def describe(self) -> str:
        """Return a readable multi-line summary (first keys of each kind)."""
        lines = [f'{self.source}: {self.matched} keys match, {len(self.missing)} missing, '
                 f'{len(self.unexpected)} unexpected, {len(self.mismatched)} shape-mismatched']
        for title, keys in (('missing', self.missing), ('unexpected', self.unexpected)):
            if keys:
                more = f' (+{len(keys) - _LIST_LIMIT} more)' if len(keys) > _LIST_LIMIT else ''
                lines.append(f'  {title}: {", ".join(keys[:_LIST_LIMIT])}{more}')
        for key, ours, theirs in self.mismatched[:_LIST_LIMIT]:
            lines.append(f'  shape of {key}: model {list(ours)}, checkpoint {list(theirs)}')
        return '\n'.join(lines)


def compare_state_dict(module: nn.Module, state_dict: Mapping[str, torch.Tensor],
                       source: str) -> LoadReport:
    """Return the ``LoadReport`` of loading ``state_dict`` into ``module`` (nothing is loaded)."""
    expected = {key: tuple(value.shape) for key, value in module.state_dict().items()}
    given = {key: tuple(value.shape) for key, value in state_dict.items()}
    mismatched = tuple((key, expected[key], given[key]) for key in expected
                       if key in given and expected[key] != given[key])
    return LoadReport(source,
                      missing=tuple(key for key in expected if key not in given),
                      unexpected=tuple(key for key in given if key not in expected),
                      mismatched=mismatched,
                      matched=sum(1 for key in expected
                                  if key in given and expected[key] == given[key]))


def load_state_dict_checked(module: nn.Module, state_dict: Mapping[str, torch.Tensor],
                            source: str, allow_missing: Sequence[str] = ()) -> LoadReport:
    """Load ``state_dict`` into ``module`` after checking every name and shape.

    Args:
        module: the receiving module.
        state_dict: tensors by key (e.g. from ``read_safetensors`` or a converter).
        source: checkpoint name used in messages.
        allow_missing: key prefixes the checkpoint may lack (those weights keep their values).

    Returns:
        The report (missing keys are all under ``allow_missing``).

    Raises:
        CheckpointError: for any unexpected key, shape mismatch or missing key outside
            ``allow_missing``; nothing is loaded then.

    """
    report = compare_state_dict(module, state_dict, source)
    not_allowed = [key for key in report.missing if not key.startswith(tuple(allow_missing))]
    if report.unexpected or report.mismatched or not_allowed:
        raise CheckpointError(f'{report.describe()}\nThe checkpoint does not fit this model; '
                              'check the configuration file or convert the checkpoint first.')
    # Missing keys were checked above against the caller's allow-list, so strict=False only
    # skips those.
    module.load_state_dict(dict(state_dict), strict=not report.missing)
    if report.missing:
        logger.info('%s: kept %d initial tensors under %s', source, len(report.missing),
                    ', '.join(allow_missing))
    return report


def read_safetensors(path: str | Path) -> dict[str, torch.Tensor]:
    """Return the tensors of a safetensors file (on the CPU).

    Raises:
        CheckpointError: when the file is missing or not a safetensors file.

    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f'{path}: no such weights file; pass a checkpoint directory made '
                              'by save_checkpoint or the converter')
    try:
        return load_file(path)
    except (SafetensorError, OSError) as exc:
        raise CheckpointError(f'{path}: not a readable safetensors file ({exc})') from exc


def config_to_yaml(config: GeometryConfig) -> str:
    """Return the YAML text of ``config`` under the ``geometry:`` section."""
    def plain(value: object) -> object:
        if isinstance(value, dict):
            return {key: plain(item) for key, item in value.items()}
        if isinstance(value, (tuple, list)):
            return [plain(item) for item in value]
        return value

    return yaml.safe_dump({GEOMETRY_SECTION: plain(asdict(config))}, sort_keys=False)


def save_checkpoint(model: GeometryModel, directory: str | Path,
                    overwrite: bool = False) -> Path:
    """Write ``model``'s weights and resolved configuration to ``directory`` atomically.

    Raises:
        InputError: when ``directory`` exists and ``overwrite`` is False.

    """
    directory = Path(directory)
    tensors = {key: value.detach().to('cpu').contiguous()
               for key, value in model.state_dict().items()}
    with atomic_directory(directory, overwrite=overwrite) as staging:
        staging.mkdir()
        save_file(tensors, staging / WEIGHTS_FILE, metadata={'format': 'pt'})
        (staging / CONFIG_FILE).write_text(config_to_yaml(model.config), encoding='utf-8')
    return directory


def load_checkpoint(directory: str | Path, device: str | torch.device = 'cpu') -> GeometryModel:
    """Build the model described by ``directory/config.yaml`` and load its weights strictly.

    Raises:
        ConfigError: for a bad configuration file.
        CheckpointError: for missing or non-matching weights.

    """
    directory = Path(directory)
    model = GeometryModel(load_geometry_config(directory / CONFIG_FILE))
    load_state_dict_checked(model, read_safetensors(directory / WEIGHTS_FILE), str(directory))
    return model.to(device).eval()
