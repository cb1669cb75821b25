"""Initialise the appearance ViT from a WiLoR checkpoint and save an InfiniHand checkpoint.

    python -m infinihand_ros.model.hand.convert_wilor --wilor wilor_final.ckpt \
        --out checkpoints/infinihand_wilor [--geometry paper --hand-branch paper]

The appearance ViT mirrors WiLoR's backbone name for name, so WiLoR's ``backbone.X`` loads into
our ``hand_branch.backbone.X`` by identity, strictly: every backbone key must exist on both sides
with the same shape. WiLoR's other keys are reported, grouped, and not used: ``refine_net``
(WiLoR's refinement head; ours differs), ``mano`` (MANO buffers, licensed data), ``discriminator``
(training only) and ``other``. Everything else of our model keeps its seeded initialisation.
The file is read with ``torch.load(weights_only=True)``, only because the user names it.
"""

import argparse
from collections.abc import Mapping
from dataclasses import dataclass
import logging
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.model.checkpoint import compare_state_dict
from infinihand_ros.model.checkpoint import load_state_dict_checked
from infinihand_ros.model.checkpoint import LoadReport
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.convert import read_torch_checkpoint
from infinihand_ros.model.hand.appearance_vit import AppearanceViT
from infinihand_ros.model.hand.config import AppearanceViTConfig
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.infinihand_checkpoint import save_infinihand_checkpoint
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs
import torch
from torch import nn

logger = logging.getLogger(__name__)

#: WiLoR's backbone attribute; ours has the same name inside ``HandBranch``.
BACKBONE: Final = 'backbone'
#: Key of the model weights in a Lightning checkpoint, and DataParallel's key prefix.
LIGHTNING_STATE_KEY: Final = 'state_dict'
#: Groups of WiLoR keys that are not used, by key prefix; anything else is ``other``.
UNUSED_GROUPS: Final = (('refine_net', 'refine_net.'), ('mano', 'mano.'),
                        ('discriminator', 'discriminator.'))
OTHER_GROUP: Final = 'other'
#: Our modules that never come from WiLoR (the hand models are the user's, not weights).
_NOT_WEIGHTS: Final = ('hand_models',)
_EXTRACT_HINT: Final = ('if the checkpoint holds training objects that weights-only loading '
                        'refuses, save its "state_dict" entry alone with torch.save in a '
                        'trusted environment and pass that file')


@dataclass(frozen=True)
class WilorConversion:
    """What a WiLoR conversion loaded, left out and left at initialisation.

    Attributes:
        report: the checked load of WiLoR's ``backbone.*`` into our appearance ViT.
        unused: WiLoR keys not used, by group (refine_net, mano, discriminator, other).
        initialised: our modules that keep their seeded initial weights.

    """

    report: LoadReport
    unused: dict[str, tuple[str, ...]]
    initialised: tuple[str, ...]

    def describe(self) -> str:
        """Return a readable multi-line summary."""
        lines = [f'loaded {self.report.matched} WiLoR backbone tensors into '
                 f'hand_branch.{BACKBONE}']
        lines += [f'unused WiLoR {group}: {len(keys)} keys' for group, keys in self.unused.items()
                  if keys]
        lines.append(f'seeded initialisation kept: {", ".join(self.initialised)}')
        return '\n'.join(lines)


def read_wilor_checkpoint(path: str | Path) -> dict[str, torch.Tensor]:
    """Return WiLoR's tensors by key, unwrapped from Lightning's ``state_dict``, no ``module.``.

    Raises:
        CheckpointError: when the file is missing, cannot be loaded with ``weights_only=True``
            or holds no mapping of tensors.

    """
    return read_torch_checkpoint(path, LIGHTNING_STATE_KEY, 'WiLoR checkpoint', _EXTRACT_HINT)


def group_unused_keys(state_dict: Mapping[str, torch.Tensor]) -> dict[str, tuple[str, ...]]:
    """Return WiLoR's non-backbone keys by group (every group present, maybe empty)."""
    groups: dict[str, list[str]] = {name: [] for name, _ in UNUSED_GROUPS}
    groups[OTHER_GROUP] = []
    for key in state_dict:
        if key.startswith(f'{BACKBONE}.'):
            continue
        group = next((name for name, prefix in UNUSED_GROUPS if key.startswith(prefix)),
                     OTHER_GROUP)
        groups[group].append(key)
    return {name: tuple(keys) for name, keys in groups.items()}


def _wilor_view(backbone: AppearanceViT) -> nn.Module:
    """Return ``backbone`` seen under WiLoR's attribute name: its keys are WiLoR's keys."""
    return nn.ModuleDict({BACKBONE: backbone})


def _backbone_tensors(state_dict: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Return WiLoR's ``backbone.*`` entries."""
    return {key: value for key, value in state_dict.items() if key.startswith(f'{BACKBONE}.')}


def check_wilor_backbone(config: AppearanceViTConfig, state_dict: Mapping[str, torch.Tensor],
                         source: str) -> None:
    """Check WiLoR's backbone keys and shapes against a ViT of ``config`` (built on meta).

    Raises:
        CheckpointError: naming every backbone key that is missing, unexpected or of another
            shape (e.g. a tiny hand-branch config against WiLoR's ViT-H).

    """
    with torch.device('meta'):
        vit = AppearanceViT(config, default_cam_scale=1.0)  # shapes only
    report = compare_state_dict(_wilor_view(vit), _backbone_tensors(state_dict), source)
    if not report.exact:
        raise CheckpointError(f'{report.describe()}\nThe WiLoR backbone does not fit the '
                              'hand-branch config; WiLoR releases a ViT-H/16 on 256x192 crops: '
                              'use the paper hand-branch config (--hand-branch paper)')


def load_wilor_backbone(model: InfiniHandModel, state_dict: Mapping[str, torch.Tensor],
                        source: str) -> WilorConversion:
    """Load WiLoR's ``backbone.*`` tensors into ``model``'s appearance ViT, strictly.

    Raises:
        CheckpointError: as ``check_wilor_backbone``; nothing is loaded then.

    """
    backbone = model.hand_branch.backbone
    check_wilor_backbone(backbone.config, state_dict, source)
    report = load_state_dict_checked(_wilor_view(backbone), _backbone_tensors(state_dict),
                                     source)
    kept = [f'geometry.{name}' for name, _ in model.geometry.named_children()]
    kept += [f'hand_branch.{name}' for name, _ in model.hand_branch.named_children()
             if name not in (BACKBONE, *_NOT_WEIGHTS)]
    return WilorConversion(report, group_unused_keys(state_dict), tuple(kept))


def convert_wilor(wilor_path: str | Path, output_dir: str | Path,
                  geometry_config: GeometryConfig, hand_config: HandBranchConfig,
                  seed: int = 0, overwrite: bool = False) -> WilorConversion:
    """Build a seeded model, load WiLoR's backbone into it and save our checkpoint.

    Args:
        wilor_path: WiLoR Lightning checkpoint (``.ckpt``) or its state dict.
        output_dir: checkpoint directory to create (see ``infinihand_checkpoint``).
        geometry_config: geometry-branch sizes.
        hand_config: hand-branch sizes; its appearance ViT must match the checkpoint.
        seed: seed of every weight that does not come from WiLoR.
        overwrite: replace an existing ``output_dir``.

    Raises:
        CheckpointError: for an unreadable checkpoint or a backbone that does not fit.
        InputError: when ``output_dir`` exists and ``overwrite`` is False.

    """
    state_dict = read_wilor_checkpoint(wilor_path)
    # Fail before spending minutes initialising a paper-size model.
    check_wilor_backbone(hand_config.appearance, state_dict, str(wilor_path))
    model = build_infinihand_model(geometry_config, hand_config, seed=seed)
    conversion = load_wilor_backbone(model, state_dict, str(wilor_path))
    save_infinihand_checkpoint(model, output_dir, overwrite=overwrite)
    return conversion


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Parse and validate the command line (exits with a one-line error)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--wilor', type=Path, required=True, help='WiLoR checkpoint (.ckpt)')
    parser.add_argument('--out', type=Path, required=True, help='checkpoint directory to write')
    parser.add_argument('--geometry', default='paper', help='tiny | paper | model YAML path')
    parser.add_argument('--hand-branch', default='paper',
                        help='tiny | paper | hand-branch YAML path (WiLoR needs paper sizes)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the non-WiLoR weights')
    parser.add_argument('--overwrite', action='store_true')
    args = parser.parse_args(argv)
    if not args.wilor.is_file():
        parser.error(f'--wilor {args.wilor}: no such file')
    if args.out.exists() and not args.overwrite:
        parser.error(f'--out {args.out}: already exists; pass --overwrite to replace it')
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the converter CLI; return the process exit status."""
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    try:
        geometry_config, hand_config = load_branch_configs(args.geometry, args.hand_branch)
        conversion = convert_wilor(args.wilor, args.out, geometry_config, hand_config,
                                   seed=args.seed, overwrite=args.overwrite)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    print(f'{args.out}: {conversion.describe()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
