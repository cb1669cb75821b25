"""Parameter counts and state-dict keys of a model configuration, without allocating weights.

    python -m infinihand_ros.model.io.summary --config config/model_paper.yaml [--json]

The model is built on PyTorch's meta device, so even the paper configuration costs no memory.
``--json`` prints ``{"params": {<top-level module>: count, ..., "total": count},
"keys": {<state-dict key>: [shape, ...]}}``; otherwise a table of counts.
"""

import argparse
import json
from pathlib import Path
import sys

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.geometry_model import GeometryModel
import torch


def summarize(config_path: str | Path) -> dict[str, dict[str, object]]:
    """Return ``{"params": {...}, "keys": {...}}`` for the configuration at ``config_path``.

    Raises:
        ConfigError: for a bad configuration file.

    """
    config = load_geometry_config(config_path)
    with torch.device('meta'):
        model = GeometryModel(config)
    params: dict[str, object] = {
        name: sum(parameter.numel() for parameter in child.parameters())
        for name, child in model.named_children()}
    params['total'] = sum(parameter.numel() for parameter in model.parameters())
    keys = {key: list(tensor.shape) for key, tensor in model.state_dict().items()}
    return {'params': params, 'keys': keys}


def main(argv: list[str] | None = None) -> int:
    """Print the summary of ``--config``; return the process exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--config', type=Path, required=True, help='model YAML file')
    parser.add_argument('--json', action='store_true', help='print JSON with every key')
    args = parser.parse_args(argv)
    try:
        summary = summarize(args.config)
    except ConfigError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    for name, count in summary['params'].items():
        print(f'{name:<14} {count:>15,}')
    print(f'{"keys":<14} {len(summary["keys"]):>15,}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
