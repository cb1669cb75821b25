"""Write (or check) the shipped params files of the nodes from their config dataclasses.

    python -m infinihand_ros.tools.params_files [--write]

``config/estimator.yaml`` and ``config/bundle_adjustment.yaml`` are generated from
``EstimatorConfig`` and ``BundleAdjustmentNodeConfig``: change a parameter in its dataclass,
then run this with ``--write``. Without it, the command lists files that differ (exit 1).
"""

import argparse
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.config import config_dir
from infinihand_ros.core.parameters import params_file_text
from infinihand_ros.ros.bundle_adjustment.config import BA_PARAMS_FILE
from infinihand_ros.ros.bundle_adjustment.config import BundleAdjustmentNodeConfig
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.config import PARAMS_FILE

_USAGE: Final = """
Pass a copy with
  --ros-args --params-file {name}
Every value is checked at start-up (types, ranges, choices); a bad one stops the node with a
message naming the parameter. Floats must be written with a decimal point (20.0, not 20).
Keyed by /** (every node name): a renamed (__node:=) or namespaced node still gets them.
Generated from {owner}:
  python -m infinihand_ros.tools.params_files --write
"""
HEADERS: Final = {
    PARAMS_FILE: (EstimatorConfig, 'Parameters of the estimator node (`ros2 run infinihand_ros '
                  'estimator`): their defaults.'),
    BA_PARAMS_FILE: (BundleAdjustmentNodeConfig, 'Parameters of the bundle-adjustment node '
                     '(`ros2 run infinihand_ros bundle_adjustment`): their\ndefaults. It '
                     'refines the keyframes the estimator sends with\n'
                     'engine.bundle_adjustment: node. Pool, solver, tracking and worker settings '
                     'are those of\nthe BA YAML named by `config`.'),
}


def expected_files() -> dict[str, str]:
    """Return each params file's name and the text its dataclass gives."""
    texts = {}
    for name, (config_type, intro) in HEADERS.items():
        owner = f'{config_type.__module__}.{config_type.__name__}'
        usage = _USAGE.format(name=name, owner=owner)
        texts[name] = params_file_text(config_type, intro + usage)
    return texts


def main(argv: list[str] | None = None) -> int:
    """Write the files with ``--write``; else return 1 when one differs from its dataclass."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--write', action='store_true', help='rewrite the files in config/')
    parser.add_argument('--config-dir', type=Path, default=config_dir(),
                        help='folder of the params files (default: the package config/)')
    args = parser.parse_args(argv)
    stale = []
    for name, text in expected_files().items():
        path = args.config_dir / name
        if args.write:
            atomic_write_bytes(path, text.encode())
        elif not path.is_file() or path.read_text() != text:
            stale.append(str(path))
    for path in stale:
        print(f'{path} differs from its dataclass; run with --write', file=sys.stderr)
    return 1 if stale else 0


if __name__ == '__main__':
    sys.exit(main())
