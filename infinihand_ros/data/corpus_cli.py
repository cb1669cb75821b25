"""``build_corpus``: our synthetic sequences (more adapters to come) into the unified corpus.

    build_corpus --out CORPUS --synthetic DIR [DIR ...] [--config config/corpus.yaml]

Settings come from ``config/corpus.yaml``. Re-running with the same ``--out`` resumes: decided
sequences are skipped. Prints the number of Stage I / Stage II sequences and the manifest path.
"""

import argparse
import logging
from pathlib import Path
import sys

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.data.adapters.synthetic import iter_synthetic
from infinihand_ros.data.cleaning import CleaningConfig
from infinihand_ros.data.corpus_builder import build_corpus
from infinihand_ros.data.corpus_builder import BuildSettings
from infinihand_ros.data.corpus_builder import CorpusConfig
from infinihand_ros.data.corpus_builder import MANIFEST_FILE
from infinihand_ros.data.mano_fit import ManoFitConfig
from infinihand_ros.mano.hand_model import build_hand_model
from infinihand_ros.mano.hand_model import load_hand_model_config
import torch


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser."""
    parser = argparse.ArgumentParser(prog='build_corpus', description=__doc__.splitlines()[0])
    parser.add_argument('--out', required=True, type=Path, help='corpus directory')
    parser.add_argument('--synthetic', nargs='+', type=Path, default=[],
                        help='synthetic sample directories (or folders holding them)')
    parser.add_argument('--config', type=Path, default=None,
                        help='settings file (default: config/corpus.yaml)')
    return parser


def validate_args(args: argparse.Namespace) -> tuple[BuildSettings, Path]:
    """Check the inputs exist and load the settings; return them and the config path."""
    if not args.synthetic:
        raise InfiniHandError('no input: give --synthetic DIR (more adapters will follow)')
    missing = [str(path) for path in args.synthetic if not path.exists()]
    if missing:
        raise InfiniHandError(f'--synthetic: no such path(s) {missing}')
    path = args.config or config_dir() / 'corpus.yaml'
    settings = BuildSettings(corpus=load_config(path, 'corpus', CorpusConfig),
                             mano_fit=load_config(path, 'mano_fit', ManoFitConfig),
                             cleaning=load_config(path, 'cleaning', CleaningConfig))
    return settings, path


def main(argv: list[str] | None = None) -> int:
    """Build (or resume) the corpus; exit 1 with one line on a bad input."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        settings, config_path = validate_args(args)
        hand_config = load_hand_model_config(config_path)
        models = tuple(build_hand_model(hand_config, side).to(torch.float64) for side in (0, 1))
        manifest = build_corpus(iter_synthetic(args.synthetic), args.out, models, settings)
    except InfiniHandError as exc:
        print(f'build_corpus: {exc}', file=sys.stderr)
        return 1
    print(f'{len(manifest["stage_1"])} Stage I sequences, {len(manifest["stage_2"])} Stage II; '
          f'{len(manifest["review"])} to review, {len(manifest["discarded"])} discarded: '
          f'{args.out / MANIFEST_FILE}')
    return 0
