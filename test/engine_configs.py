"""Engine settings of tests that run the seeded, untrained tiny model on synthetic frames."""

import dataclasses

from infinihand_ros.engine.config import DetectionConfig
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import ModelSelection
from infinihand_ros.engine.settings import build_engine_config


def seeded_tiny(**changes: object) -> EngineConfig:
    """Return the reference path with seeded tiny weights and ``changes``.

    The synthetic profile (the paper's hand branch) with the geometry branch on every frame, in
    float32, each hand mask boxed whole: the tests' numbers do not move with the bundled model
    or the live defaults.
    """
    return dataclasses.replace(
        build_engine_config('synthetic'), geometry_interval=1, geometry_lag=0,
        cpu_precision='fp32', model=ModelSelection(geometry='tiny', checkpoint=None),
        detection=DetectionConfig(peak_region=False, region_join_px=0), **changes)
