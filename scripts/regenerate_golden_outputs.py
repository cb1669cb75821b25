"""Rewrite test/model/golden/tiny_outputs.safetensors from the current network code.

    python scripts/regenerate_golden_outputs.py

Run it only after a deliberate numerical change to the network, and commit the file with it.
The case itself (frames, boxes, stored tensors) lives beside its test, in
``test/model/golden_outputs.py``, so the test and this script compute the same thing.
"""

import importlib.util
from pathlib import Path

from infinihand_ros.core.atomic_io import atomic_write_bytes
from safetensors.torch import save

CASE_PATH = Path(__file__).resolve().parents[1] / 'test' / 'model' / 'golden_outputs.py'


def main() -> None:
    """Compute the golden case and write it atomically."""
    spec = importlib.util.spec_from_file_location('golden_outputs', CASE_PATH)
    case = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(case)
    tensors = {name: value.float().contiguous()
               for name, value in case.compute_golden_outputs().items()}
    atomic_write_bytes(case.GOLDEN_PATH, save(tensors))
    print(f'wrote {case.GOLDEN_PATH} ({case.GOLDEN_PATH.stat().st_size} bytes, '
          f'{len(tensors)} tensors)')


if __name__ == '__main__':
    main()
