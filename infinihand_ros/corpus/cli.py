"""``build_corpus``: public datasets, our own data and unlabeled bags into the unified corpus.

    build_corpus --out CORPUS [--synthetic DIR ...] [--lerobot DIR ...] [--dexycb DIR ...]
                 [--ho3d DIR ...] [--egodex DIR ...] [--arctic DIR ...] [--hot3d DIR ...]
                 [--from-bags BAG ...] [--keypoints mediapipe|none] [--config config/corpus.yaml]

Each dataset flag takes roots in that dataset's published layout (``data/adapters/``);
``--from-bags`` pseudo-labels unlabeled rosbag2 recordings with MediaPipe Hands
(``data/pseudo_labels.py``). Sequences are cleaned against MediaPipe Hands unless
``--keypoints none``. Settings come from ``config/corpus.yaml``. Re-running with the same
``--out`` resumes: decided sequences are skipped. Prints the stage counts and the manifest path.
"""

import argparse
from collections.abc import Iterator
import contextlib
import logging
from pathlib import Path
import sys

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.corpus.adapters.registry import AdapterContext
from infinihand_ros.corpus.adapters.registry import ADAPTERS
from infinihand_ros.corpus.builder import build_corpus
from infinihand_ros.corpus.builder import BuildSettings
from infinihand_ros.corpus.builder import CorpusConfig
from infinihand_ros.corpus.builder import MANIFEST_FILE
from infinihand_ros.corpus.cleaning import CleaningConfig
from infinihand_ros.corpus.pseudo_labels import pseudo_label_bag
from infinihand_ros.corpus.pseudo_labels import PseudoLabelConfig
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.engine.hands.keypoints import KeypointSource
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeConfig
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeKeypointSource
from infinihand_ros.mano.fit import ManoFitConfig
from infinihand_ros.mano.hand_model import build_hand_model
from infinihand_ros.mano.hand_model import HandModelConfig
from infinihand_ros.mano.hand_model import load_hand_model_config
from infinihand_ros.mano.mano_file import load_mano_data
import torch

KEYPOINT_SOURCES = ('mediapipe', 'none')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser."""
    parser = argparse.ArgumentParser(prog='build_corpus', description=__doc__.splitlines()[0])
    parser.add_argument('--out', required=True, type=Path, help='corpus directory')
    for name in ADAPTERS:
        parser.add_argument(f'--{name}', nargs='+', type=Path, default=[],
                            help=f'{name} dataset roots (or folders holding them)')
    parser.add_argument('--from-bags', nargs='+', type=Path, default=[],
                        help='unlabeled rosbag2 recordings to pseudo-label')
    parser.add_argument('--keypoints', choices=KEYPOINT_SOURCES, default='mediapipe',
                        help='independent 2D source for cleaning (default mediapipe)')
    parser.add_argument('--config', type=Path, default=None,
                        help='settings file (default: config/corpus.yaml)')
    return parser


def validate_args(args: argparse.Namespace) -> tuple[BuildSettings, Path]:
    """Check the inputs exist and load the settings; return them and the config path."""
    inputs = {name: getattr(args, name) for name in ADAPTERS} | {'from-bags': args.from_bags}
    if not any(inputs.values()):
        raise InfiniHandError(f'no input: give at least one of '
                              f'{", ".join("--" + name for name in inputs)}')
    if args.from_bags and args.keypoints == 'none':
        raise InfiniHandError('--from-bags needs a 2D source; drop --keypoints none')
    for name, paths in inputs.items():
        missing = [str(path) for path in paths if not path.exists()]
        if missing:
            raise InfiniHandError(f'--{name}: no such path(s) {missing}')
    path = args.config or config_dir() / 'corpus.yaml'
    settings = BuildSettings(corpus=load_config(path, 'corpus', CorpusConfig),
                             mano_fit=load_config(path, 'mano_fit', ManoFitConfig),
                             cleaning=load_config(path, 'cleaning', CleaningConfig))
    return settings, path


def _context(config: HandModelConfig) -> AdapterContext:
    """MANO arrays for MANO-only datasets when MANO files are configured."""
    if not config.mano_dir:
        return AdapterContext()
    folder = Path(config.mano_dir).expanduser()
    mano = tuple(load_mano_data(folder / f'MANO_{side}.pkl') for side in ('LEFT', 'RIGHT'))
    return AdapterContext(mano, keep_mano=config.kind == 'mano')


def _sequences(args: argparse.Namespace, context: AdapterContext,
               source: KeypointSource | None, config_path: Path) -> Iterator[CorpusSequence]:
    for name, adapter in ADAPTERS.items():
        if getattr(args, name):
            yield from adapter(getattr(args, name), context)
    labels = load_config(config_path, 'pseudo_labels', PseudoLabelConfig)
    for bag in args.from_bags:
        yield pseudo_label_bag(bag, source, labels)


def main(argv: list[str] | None = None) -> int:
    """Build (or resume) the corpus; exit 1 with one line on a bad input."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        settings, config_path = validate_args(args)
        hand_config = load_hand_model_config(config_path)
        models = tuple(build_hand_model(hand_config, side).to(torch.float64) for side in (0, 1))
        with contextlib.ExitStack() as stack:
            source = None
            if args.keypoints == 'mediapipe':
                source = stack.enter_context(MediaPipeKeypointSource(
                    load_config(config_path, 'mediapipe', MediaPipeConfig)))
            sequences = _sequences(args, _context(hand_config), source, config_path)
            manifest = build_corpus(sequences, args.out, models, settings, source)
    except InfiniHandError as exc:
        print(f'build_corpus: {exc}', file=sys.stderr)
        return 1
    print(f'{len(manifest["stage_1"])} Stage I sequences, {len(manifest["stage_2"])} Stage II; '
          f'{len(manifest["review"])} to review, {len(manifest["discarded"])} discarded: '
          f'{args.out / MANIFEST_FILE}')
    return 0
