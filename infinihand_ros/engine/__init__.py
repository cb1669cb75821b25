"""The streaming engine: frames in, per-frame camera and world-space hand results out.

``StreamingEngine()`` runs the ``live`` profile (real camera images); other uses name theirs:
``StreamingEngine(build_engine_config('synthetic'))``.
"""

from typing import Any

__all__ = ['StreamingEngine', 'build_engine_config']


def __getattr__(name: str) -> Any:
    """Import the public names on first use (the engine pulls in torch and the model)."""
    if name == 'StreamingEngine':
        from infinihand_ros.engine.streaming_engine import StreamingEngine
        return StreamingEngine
    if name == 'build_engine_config':
        from infinihand_ros.engine.settings import build_engine_config
        return build_engine_config
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
