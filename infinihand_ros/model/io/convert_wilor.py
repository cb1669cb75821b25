"""Convert a WiLoR checkpoint into a crop-encoder checkpoint (the appearance ViT's weights).

    python -m infinihand_ros.model.io.convert_wilor --wilor wilor_final.ckpt \
        --out checkpoints/wilor_crop_encoder [--hand-branch paper]

The appearance ViT mirrors WiLoR's backbone name for name, so WiLoR's ``backbone.X`` becomes our
``hand_branch.backbone.X`` by identity, strictly: every backbone key must exist on both sides
with the same shape (checked on the meta device). WiLoR's other keys are reported, grouped, and
not used: ``refine_net`` (WiLoR's refinement head; ours differs), ``mano`` (MANO buffers,
licensed data), ``discriminator`` (training only) and ``other``. The output
(``model/io/checkpoint.py`` format) holds ``hand_branch.backbone.*`` and the hand-branch config
it fits; ``model/io/compose.py`` loads it with a geometry checkpoint, the rest seeded. The file
is read with ``torch.load(weights_only=True)``, only because the user names it.
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
from infinihand_ros.model.hand.appearance_vit import AppearanceViT
from infinihand_ros.model.hand.config import AppearanceViTConfig
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import HAND_BRANCH_PREFIX
from infinihand_ros.model.io.checkpoint import compare_state_dict
from infinihand_ros.model.io.checkpoint import LoadReport
from infinihand_ros.model.io.checkpoint import write_checkpoint
from infinihand_ros.model.io.torch_checkpoint import read_torch_checkpoint
import torch
from torch import nn

logger = logging.getLogger(__name__)

#: WiLoR's backbone attribute; ours has the same name inside ``HandBranch``.
BACKBONE: Final = 'backbone'
#: Our key prefix of the crop encoder in the whole model.
CROP_ENCODER_PREFIX: Final = f'{HAND_BRANCH_PREFIX}{BACKBONE}.'
#: Key of the model weights in a Lightning checkpoint.
LIGHTNING_STATE_KEY: Final = 'state_dict'
#: Groups of WiLoR keys that are not used, by key prefix; anything else is ``other``.
UNUSED_GROUPS: Final = (('refine_net', 'refine_net.'), ('mano', 'mano.'),
                        ('discriminator', 'discriminator.'))
OTHER_GROUP: Final = 'other'
_EXTRACT_HINT: Final = ('if the checkpoint holds training objects that weights-only loading '
                        'refuses, save its "state_dict" entry alone with torch.save in a '
                        'trusted environment and pass that file')


@dataclass(frozen=True)
class WilorConversion:
    """What a WiLoR conversion kept and left out.

    Attributes:
        report: the check of WiLoR's ``backbone.*`` against our appearance ViT.
        unused: WiLoR keys not used, by group (refine_net, mano, discriminator, other).

    """

    report: LoadReport
    unused: dict[str, tuple[str, ...]]

    def describe(self) -> str:
        """Return a readable multi-line summary."""
        lines = [f'converted {self.report.matched} WiLoR backbone tensors into '
                 f'{CROP_ENCODER_PREFIX}*']
        lines += [f'unused WiLoR {group}: {len(keys)} keys' for group, keys in self.unused.items()
                  if keys]
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


def _backbone_tensors(state_dict: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Return WiLoR's ``backbone.*`` entries."""
    return {key: value for key, value in state_dict.items() if key.startswith(f'{BACKBONE}.')}


def check_wilor_backbone(config: AppearanceViTConfig, state_dict: Mapping[str, torch.Tensor],
                         source: str) -> LoadReport:
    """Check WiLoR's backbone keys and shapes against a ViT of ``config`` (built on meta).

    Raises:
        CheckpointError: naming every backbone key that is missing, unexpected or of another
            shape (e.g. a tiny hand-branch config against WiLoR's ViT-H).

    """
    with torch.device('meta'):
        vit = AppearanceViT(config, default_cam_scale=1.0)  # shapes only
    report = compare_state_dict(nn.ModuleDict({BACKBONE: vit}), _backbone_tensors(state_dict),
                                source)
    if not report.exact:
        raise CheckpointError(f'{report.describe()}\nThe WiLoR backbone does not fit the '
                              'hand-branch config; WiLoR releases a ViT-H/16 on 256x192 crops: '
                              'use the paper hand-branch config (--hand-branch paper)')
    return report


def convert_wilor(wilor_path: str | Path, output_dir: str | Path,
                  hand_config: HandBranchConfig, overwrite: bool = False) -> WilorConversion:
    """Check WiLoR's backbone against ``hand_config`` and save it as a crop-encoder checkpoint.

    Args:
        wilor_path: WiLoR Lightning checkpoint (``.ckpt``) or its state dict.
        output_dir: checkpoint directory to create (``model/io/checkpoint.py`` format).
        hand_config: hand-branch sizes; its appearance ViT must match the checkpoint. It is
            saved with the weights and defines the hand branch they are loaded into.
        overwrite: replace an existing ``output_dir``.

    Raises:
        CheckpointError: for an unreadable checkpoint or a backbone that does not fit.
        InputError: when ``output_dir`` exists and ``overwrite`` is False.

    """
    state_dict = read_wilor_checkpoint(wilor_path)
    report = check_wilor_backbone(hand_config.appearance, state_dict, str(wilor_path))
    tensors = {HAND_BRANCH_PREFIX + key: value
               for key, value in _backbone_tensors(state_dict).items()}
    write_checkpoint(output_dir, tensors, hand_config=hand_config,
                     source=f'wilor: {Path(wilor_path).name}', overwrite=overwrite)
    return WilorConversion(report, group_unused_keys(state_dict))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Parse and validate the command line (exits with a one-line error)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--wilor', type=Path, required=True, help='WiLoR checkpoint (.ckpt)')
    parser.add_argument('--out', type=Path, required=True, help='checkpoint directory to write')
    parser.add_argument('--hand-branch', default='paper',
                        help='tiny | paper | hand-branch YAML path (WiLoR needs paper sizes)')
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
        conversion = convert_wilor(args.wilor, args.out, load_hand_branch_config(args.hand_branch),
                                   overwrite=args.overwrite)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    print(f'{args.out}: {conversion.describe()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
