"""What a BA child process has imported, run in the child (this module imports no torch)."""

import sys

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.features import FeatureCache


def heavy_modules(request: object, config: BAConfig, cache: FeatureCache) -> list[str]:
    """Return which of torch, roma and mediapipe the child has imported after BA's modules."""
    import infinihand_ros.ba.worker  # noqa: F401 - what the BA process imports to run BA
    return [name for name in ('torch', 'roma', 'mediapipe') if name in sys.modules]
