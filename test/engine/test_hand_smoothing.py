"""Smoothing of the hand outputs per side (engine/output/smoothing.py)."""

import math

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.engine.output.smoothing import HandSmoother
import numpy as np
from result_builders import make_hand
from result_builders import PALM_JOINTS

S = 1_000_000_000
HALF = 1.0 / (2.0 * math.pi)  # alpha 0.5 at dt = 1 s


def test_none_passes_hands_unchanged() -> None:
    """Mode none returns the very same hands."""
    hands = (make_hand(LEFT),)
    assert HandSmoother(SmoothingConfig()).apply(hands, 0) is hands


def test_one_euro_smooths_world_joints_and_restarts_after_a_gap() -> None:
    """The second sample moves half way; after a frame without the hand it restarts."""
    smoother = HandSmoother(SmoothingConfig(mode='one_euro', min_cutoff_hz=HALF, beta=0.0))
    smoother.apply((make_hand(RIGHT),), 0)
    moved = (make_hand(RIGHT, joints_world=PALM_JOINTS + 1.0),)
    np.testing.assert_allclose(smoother.apply(moved, S)[0].joints_world, PALM_JOINTS + 0.5)
    smoother.apply((make_hand(LEFT),), 2 * S)  # right not seen: its filter restarts
    np.testing.assert_allclose(smoother.apply(moved, 3 * S)[0].joints_world, PALM_JOINTS + 1.0)
