"""The seeded tiny model still computes the committed golden outputs (numerical regressions).

After a deliberate change to the network's numerics, regenerate the file with
``python scripts/regenerate_golden_outputs.py`` and commit it with the change.
"""

from golden_outputs import compute_golden_outputs
from golden_outputs import GOLDEN_PATH
from safetensors.torch import load_file
import torch


def test_tiny_model_outputs_equal_the_golden_file() -> None:
    """Every stored tensor matches (float32 on the CPU)."""
    golden = load_file(GOLDEN_PATH)
    outputs = compute_golden_outputs()
    assert sorted(golden) == sorted(outputs)
    for name, expected in golden.items():
        torch.testing.assert_close(outputs[name].float(), expected, rtol=1e-4, atol=1e-5,
                                   msg=f'{name} changed; if on purpose, regenerate the file')
