"""Convert a LingBot-Map or VGGT checkpoint (.pt) into our safetensors + config checkpoint.

    python -m infinihand_ros.model.convert --source lingbot-map --input lingbot-map-long.pt \
        --config config/model_paper.yaml --output checkpoints/geometry_paper

Our module tree mirrors LingBot-Map name for name, so keys map by identity after unwrapping
``"model"`` and stripping ``module.``. Expected differences, and nothing else, are accepted:

- LingBot-Map: ``point_head.*`` (only when it was trained with ``enable_point``) is dropped.
- VGGT: ``point_head.*`` and ``track_head.*`` are dropped; ``aggregator.scale_token`` does not
  exist and is added as zeros (slot 0 = anchor frames, slot 1 = later frames). VGGT's global
  attention uses 2D RoPE (set ``aggregator.global_rope: spatial2d``), its camera head was trained
  bidirectionally (ours is causal) and its pose encoding is world-to-camera.
- Both: ``mask_head.*`` is not in the source; it is initialised from the depth head with a fresh
  final layer (paper Sec. 3.2).

Pickle files are read only when the user names them, with ``torch.load(weights_only=True)``.
"""

import argparse
from collections.abc import Callable
from collections.abc import Mapping
from dataclasses import dataclass
import logging
from pathlib import Path
import pickle
import sys

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.model.checkpoint import load_state_dict_checked
from infinihand_ros.model.checkpoint import LoadReport
from infinihand_ros.model.checkpoint import save_checkpoint
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.heads.mask_head import init_mask_head_from_depth
import torch

logger = logging.getLogger(__name__)

KEPT_PREFIXES = ('aggregator.', 'camera_head.', 'depth_head.')
WRAPPER_KEY = 'model'
PARALLEL_PREFIX = 'module.'
SCALE_TOKEN_KEY = 'aggregator.scale_token'
CAMERA_TOKEN_KEY = 'aggregator.camera_token'
FRESH_PREFIXES = ('mask_head.',)


@dataclass(frozen=True)
class Conversion:
    """A converted state dict and what the conversion changed.

    Attributes:
        state_dict: tensors under our key names.
        dropped: source keys deliberately left out.
        added: keys created by the converter (not in the source).

    """

    state_dict: dict[str, torch.Tensor]
    dropped: tuple[str, ...]
    added: tuple[str, ...]


def read_torch_checkpoint(path: str | Path, wrapper_key: str = WRAPPER_KEY,
                          what: str = 'checkpoint', hint: str = 'pass the model state dict'
                          ) -> dict[str, torch.Tensor]:
    """Return the tensors of a pickle checkpoint, unwrapped and without ``module.`` prefixes.

    Loaded only with ``torch.load(weights_only=True)``, i.e. tensors and plain containers.

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


def _split(state_dict: Mapping[str, torch.Tensor], dropped_prefixes: tuple[str, ...],
           source: str) -> tuple[dict[str, torch.Tensor], tuple[str, ...]]:
    """Return (kept tensors, dropped keys); raise on keys of neither kind."""
    kept = {key: value for key, value in state_dict.items() if key.startswith(KEPT_PREFIXES)}
    dropped = tuple(key for key in state_dict if key.startswith(dropped_prefixes))
    unknown = [key for key in state_dict if key not in kept and key not in dropped]
    if unknown:
        raise CheckpointError(f'{source} checkpoint: unexpected keys {unknown[:10]} '
                              f'({len(unknown)} in all); is --source right?')
    return kept, dropped


def convert_lingbot_map(state_dict: Mapping[str, torch.Tensor]) -> Conversion:
    """Map a LingBot-Map (GCTStream) state dict to ours: identity, ``point_head.*`` dropped."""
    kept, dropped = _split(state_dict, ('point_head.',), 'LingBot-Map')
    return Conversion(kept, dropped, ())


def convert_vggt(state_dict: Mapping[str, torch.Tensor]) -> Conversion:
    """Map a VGGT state dict to ours: drop point/track heads, add a zero scale token.

    Raises:
        CheckpointError: when the camera token is missing or a scale token already exists
            (then it is a LingBot-Map checkpoint).

    """
    kept, dropped = _split(state_dict, ('point_head.', 'track_head.'), 'VGGT')
    if SCALE_TOKEN_KEY in kept:
        raise CheckpointError('VGGT checkpoint: it has aggregator.scale_token, so it is a '
                              'LingBot-Map checkpoint; use --source lingbot-map')
    if CAMERA_TOKEN_KEY not in kept:
        raise CheckpointError(f'VGGT checkpoint: {CAMERA_TOKEN_KEY} is missing')
    kept[SCALE_TOKEN_KEY] = torch.zeros_like(kept[CAMERA_TOKEN_KEY])
    return Conversion(kept, dropped, (SCALE_TOKEN_KEY,))


CONVERTERS: dict[str, Callable[[Mapping[str, torch.Tensor]], Conversion]] = {
    'lingbot-map': convert_lingbot_map,
    'vggt': convert_vggt,
}


def convert_checkpoint(source: str, input_path: str | Path, config_path: str | Path,
                       output_dir: str | Path, seed: int = 0,
                       overwrite: bool = False) -> tuple[Conversion, LoadReport]:
    """Convert ``input_path`` and save our checkpoint to ``output_dir``.

    Args:
        source: ``lingbot-map`` or ``vggt``.
        input_path: the upstream ``.pt`` file.
        config_path: model YAML whose ``geometry:`` section matches the checkpoint.
        output_dir: directory to create (``model.safetensors`` + ``config.yaml``).
        seed: seed of the fresh mask-head final layer.
        overwrite: replace an existing ``output_dir``.

    Raises:
        CheckpointError: for an unreadable checkpoint or any unexpected key difference.

    """
    conversion = CONVERTERS[source](read_torch_checkpoint(input_path))
    config = load_geometry_config(config_path)
    if source == 'vggt' and config.aggregator.global_rope != 'spatial2d':
        logger.warning('VGGT weights were trained with 2D RoPE in the global blocks; set '
                       'aggregator.global_rope: spatial2d in %s', config_path)
    torch.manual_seed(seed)
    model = GeometryModel(config)
    report = load_state_dict_checked(model, conversion.state_dict, str(input_path),
                                     allow_missing=FRESH_PREFIXES)
    init_mask_head_from_depth(model.mask_head, model.depth_head)
    save_checkpoint(model, output_dir, overwrite=overwrite)
    return conversion, report


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Parse and validate the command line (exits with a one-line error)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--source', choices=sorted(CONVERTERS), required=True)
    parser.add_argument('--input', type=Path, required=True, help='upstream .pt checkpoint')
    parser.add_argument('--config', type=Path, default=named_config_path('paper'),
                        help='model YAML (default: the paper configuration)')
    parser.add_argument('--output', type=Path, required=True, help='checkpoint directory')
    parser.add_argument('--overwrite', action='store_true')
    args = parser.parse_args(argv)
    if not args.input.is_file():
        parser.error(f'--input {args.input}: no such file')
    if not args.config.is_file():
        parser.error(f'--config {args.config}: no such file')
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the converter CLI; return the process exit status."""
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    try:
        conversion, report = convert_checkpoint(args.source, args.input, args.config,
                                                args.output, overwrite=args.overwrite)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    print(f'{args.output}: {report.matched} tensors converted, {len(conversion.dropped)} '
          f'dropped, {len(conversion.added)} added, {len(report.missing)} initialised fresh')
    return 0


if __name__ == '__main__':
    sys.exit(main())
