"""Convert a LingBot-Map or VGGT checkpoint (.pt) into a geometry checkpoint.

    python -m infinihand_ros.model.io.convert_lingbot_map --source lingbot-map \
        --input lingbot-map-long.pt --output checkpoints/lingbot_map_long \
        [--config config/model_paper.yaml] [--pose-direction cam_to_world|world_to_cam]

Our module tree mirrors LingBot-Map name for name, so keys map by identity after unwrapping
``"model"`` and stripping ``module.``, then take our ``geometry.`` prefix. Expected differences,
and nothing else, are accepted:

- LingBot-Map: ``point_head.*`` (only when it was trained with ``enable_point``) is dropped.
- VGGT: ``point_head.*`` and ``track_head.*`` are dropped; ``aggregator.scale_token`` does not
  exist and is added as zeros (slot 0 = anchor frames, slot 1 = later frames). Its camera head
  was trained bidirectionally (ours is causal).
- Both: ``mask_head.*`` is not in the source and not written: loading the checkpoint seeds it
  from the depth head with a fresh final layer (paper Sec. 3.2; ``model/io/compose.py``).

The output (``model/io/checkpoint.py`` format) holds ``geometry.aggregator``,
``geometry.camera_head`` and ``geometry.depth_head`` and the ``--config`` geometry section with
the conventions of the weights set: ``pose_direction`` (``UPSTREAM_POSE_DIRECTION``; evidence in
``model/pose_encoding.py``), ``preprocessing: resize_crop`` (both upstreams' default
``load_and_preprocess_images`` mode) and, for VGGT, ``aggregator.global_rope: spatial2d``.
Shapes are checked against the config on the meta device, so no model is allocated.
"""

import argparse
from collections.abc import Callable
from collections.abc import Mapping
from dataclasses import dataclass
from dataclasses import replace
import logging
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.config import RESIZE_CROP
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.infinihand_model import GEOMETRY_PREFIX
from infinihand_ros.model.io.checkpoint import compare_state_dict
from infinihand_ros.model.io.checkpoint import LoadReport
from infinihand_ros.model.io.checkpoint import write_checkpoint
from infinihand_ros.model.io.torch_checkpoint import read_torch_checkpoint
from infinihand_ros.model.pose_encoding import CAM_TO_WORLD
from infinihand_ros.model.pose_encoding import POSE_DIRECTIONS
from infinihand_ros.model.pose_encoding import WORLD_TO_CAM
import torch

logger = logging.getLogger(__name__)

LINGBOT_MAP: Final = 'lingbot-map'
VGGT: Final = 'vggt'
KEPT_PREFIXES: Final = ('aggregator.', 'camera_head.', 'depth_head.')
SCALE_TOKEN_KEY: Final = 'aggregator.scale_token'
CAMERA_TOKEN_KEY: Final = 'aggregator.camera_token'
#: Our geometry keys no upstream checkpoint has (seeded from the depth head when loaded).
MASK_HEAD_PREFIX: Final = 'mask_head.'
#: Which way each upstream's decoded ``[R | t]`` points (see ``model/pose_encoding.py``).
UPSTREAM_POSE_DIRECTION: Final = {LINGBOT_MAP: CAM_TO_WORLD, VGGT: WORLD_TO_CAM}
#: The input preprocessing each upstream was trained with (``load_and_preprocess_images``).
UPSTREAM_PREPROCESSING: Final = {LINGBOT_MAP: RESIZE_CROP, VGGT: RESIZE_CROP}
#: VGGT's global blocks use 2D RoPE; LingBot-Map's the 3D video RoPE (the config's default).
VGGT_GLOBAL_ROPE: Final = 'spatial2d'


@dataclass(frozen=True)
class Conversion:
    """A converted state dict and what the conversion changed.

    Attributes:
        state_dict: tensors under the geometry model's key names (no ``geometry.`` prefix).
        dropped: source keys deliberately left out.
        added: keys created by the converter (not in the source).

    """

    state_dict: dict[str, torch.Tensor]
    dropped: tuple[str, ...]
    added: tuple[str, ...]


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


CONVERTERS: Final[dict[str, Callable[[Mapping[str, torch.Tensor]], Conversion]]] = {
    LINGBOT_MAP: convert_lingbot_map,
    VGGT: convert_vggt,
}


def upstream_config(source: str, config: GeometryConfig,
                    pose_direction: str | None = None) -> GeometryConfig:
    """Return ``config`` with the conventions of ``source``'s weights.

    Args:
        source: ``lingbot-map`` or ``vggt``.
        config: the geometry sizes (e.g. the paper configuration).
        pose_direction: overrides ``UPSTREAM_POSE_DIRECTION[source]`` when given.

    """
    converted = replace(config, pose_direction=pose_direction or UPSTREAM_POSE_DIRECTION[source],
                        preprocessing=UPSTREAM_PREPROCESSING[source])
    if source == VGGT and config.aggregator.global_rope != VGGT_GLOBAL_ROPE:
        logger.info('VGGT weights: setting aggregator.global_rope to %s (2D RoPE in the global '
                    'blocks)', VGGT_GLOBAL_ROPE)
        converted = replace(converted,
                            aggregator=replace(config.aggregator, global_rope=VGGT_GLOBAL_ROPE))
    return converted


def check_geometry_tensors(config: GeometryConfig, state_dict: Mapping[str, torch.Tensor],
                           source: str) -> LoadReport:
    """Check converted tensors against a geometry model of ``config`` (built on meta).

    Returns:
        The report; the mask head's keys are its ``allowed_missing``.

    Raises:
        CheckpointError: naming every key that is missing, unexpected or of another shape.

    """
    with torch.device('meta'):
        model = GeometryModel(config)  # shapes only
    report = compare_state_dict(model, state_dict, source, allow_missing=(MASK_HEAD_PREFIX,))
    if not report.ok:
        raise CheckpointError(f'{report.describe()}\nThe checkpoint does not fit the geometry '
                              'config; pass the configuration it was trained with (--config)')
    return report


def convert_checkpoint(source: str, input_path: str | Path, config_path: str | Path,
                       output_dir: str | Path, overwrite: bool = False,
                       pose_direction: str | None = None) -> tuple[Conversion, LoadReport]:
    """Convert ``input_path`` and save the geometry checkpoint to ``output_dir``.

    Args:
        source: ``lingbot-map`` or ``vggt``.
        input_path: the upstream ``.pt`` file.
        config_path: model YAML whose ``geometry:`` section has the checkpoint's sizes.
        output_dir: directory to create (``model.safetensors`` + ``geometry.yaml``).
        overwrite: replace an existing ``output_dir``.
        pose_direction: record this instead of the upstream's documented direction.

    Raises:
        CheckpointError: for an unreadable checkpoint or any unexpected key difference.
        ConfigError: for a bad config file.
        InputError: when ``output_dir`` exists and ``overwrite`` is False.

    """
    if source not in CONVERTERS:
        raise CheckpointError(f'unknown source {source!r}; use one of {sorted(CONVERTERS)}')
    conversion = CONVERTERS[source](read_torch_checkpoint(input_path))
    config = upstream_config(source, load_geometry_config(config_path), pose_direction)
    report = check_geometry_tensors(config, conversion.state_dict, str(input_path))
    tensors = {GEOMETRY_PREFIX + key: value for key, value in conversion.state_dict.items()}
    write_checkpoint(output_dir, tensors, geometry_config=config,
                     source=f'{source}: {Path(input_path).name}', overwrite=overwrite)
    return conversion, report


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Parse and validate the command line (exits with a one-line error)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--source', choices=sorted(CONVERTERS), required=True)
    parser.add_argument('--input', type=Path, required=True, help='upstream .pt checkpoint')
    parser.add_argument('--config', type=Path, default=named_config_path('paper'),
                        help='model YAML with the sizes (default: the paper configuration)')
    parser.add_argument('--output', type=Path, required=True, help='checkpoint directory')
    parser.add_argument('--pose-direction', choices=POSE_DIRECTIONS, default=None,
                        help="the weights' pose direction (default: the source's, see "
                             'model/pose_encoding.py)')
    parser.add_argument('--overwrite', action='store_true')
    args = parser.parse_args(argv)
    if not args.input.is_file():
        parser.error(f'--input {args.input}: no such file')
    if not args.config.is_file():
        parser.error(f'--config {args.config}: no such file')
    if args.output.exists() and not args.overwrite:
        parser.error(f'--output {args.output}: already exists; pass --overwrite to replace it')
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the converter CLI; return the process exit status."""
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    try:
        conversion, report = convert_checkpoint(args.source, args.input, args.config,
                                                args.output, overwrite=args.overwrite,
                                                pose_direction=args.pose_direction)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    direction = args.pose_direction or UPSTREAM_POSE_DIRECTION[args.source]
    print(f'{args.output}: {report.matched} tensors converted, {len(conversion.dropped)} '
          f'dropped, {len(conversion.added)} added; pose_direction {direction}, preprocessing '
          f'{UPSTREAM_PREPROCESSING[args.source]}; geometry.mask_head is seeded from the depth '
          'head when loaded')
    return 0


if __name__ == '__main__':
    sys.exit(main())
