"""The embedded sample bag: a synthetic sequence shipped in ``data/`` as the demo's default input.

``data/sample_bag.yaml`` holds everything it is generated from (seed, frame count, sequence and bag
settings); ``data/sample_bag/`` is the bag. Regenerate it after changing the generator with
``python -m infinihand_ros.synth.sample_bag --write`` (from a source checkout).
"""

import argparse
from dataclasses import dataclass
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import package_share_dir
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.bag_sink import BagOptions
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence

SETTINGS_NAME: Final = 'sample_bag.yaml'
BAG_NAME: Final = 'sample_bag'
#: Size limit of the shipped bag (bytes).
MAX_BAG_BYTES: Final = 15 * 1024 * 1024


@dataclass(frozen=True)
class SampleSpec:
    """Seed and length of the sample sequence (section ``sample`` of ``sample_bag.yaml``)."""

    seed: int
    frames: int

    def __post_init__(self) -> None:
        if self.seed < 0 or self.frames < 1:
            raise InputError(f'sample: seed must be >= 0 and frames >= 1, got {self}')


@dataclass(frozen=True)
class SampleSettings:
    """Everything the sample bag is generated from."""

    spec: SampleSpec
    synth: SynthConfig
    bag: BagOptions


def data_dir() -> Path:
    """Return the package's ``data/`` directory (source tree, else the installed share dir)."""
    return package_share_dir('data')


def sample_bag_path() -> Path:
    """Return the path of the embedded sample bag directory."""
    return data_dir() / BAG_NAME


def load_sample_settings(path: Path | None = None) -> SampleSettings:
    """Read ``data/sample_bag.yaml`` (or ``path``)."""
    path = path or data_dir() / SETTINGS_NAME
    return SampleSettings(spec=load_config(path, 'sample', SampleSpec),
                          synth=load_config(path, 'synth', SynthConfig),
                          bag=load_config(path, 'bag', BagOptions))


def sample_sequence(settings: SampleSettings) -> SyntheticSequence:
    """Return the synthetic sequence the sample bag holds."""
    return SyntheticSequence(settings.synth, settings.spec.seed, settings.spec.frames)


def write_sample_bag(out: Path, settings: SampleSettings, overwrite: bool = False) -> int:
    """Generate the sample bag at ``out`` (atomically); return its size in bytes.

    Raises:
        InputError: if the bag exceeds ``MAX_BAG_BYTES`` (nothing is written then).

    """
    with atomic_directory(out, overwrite=overwrite) as work:
        with BagSink(work, settings.bag) as sink:
            for frame in sample_sequence(settings):
                sink.add(frame)
        size = sum(f.stat().st_size for f in work.iterdir())
        if size > MAX_BAG_BYTES:
            raise InputError(f'sample bag would be {size / 2**20:.1f} MiB, over the '
                             f'{MAX_BAG_BYTES / 2**20:.0f} MiB limit; shorten it in '
                             f'{SETTINGS_NAME}')
    return size


def main(argv: list[str] | None = None) -> int:
    """Regenerate ``data/sample_bag/`` from ``data/sample_bag.yaml``."""
    parser = argparse.ArgumentParser(prog='python -m infinihand_ros.synth.sample_bag',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--write', action='store_true', required=True,
                        help='regenerate the bag in the source tree, replacing the old one')
    parser.parse_args(argv)
    try:
        out = sample_bag_path()
        size = write_sample_bag(out, load_sample_settings(), overwrite=True)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    print(f'wrote {out} ({size / 2**20:.2f} MiB)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
