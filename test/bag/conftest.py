"""Fixtures of the bag tests: one typestore per session and seeded builders of core results."""

from collections.abc import Callable

from bag_builders import random_frame
from bag_builders import random_keyframes
from infinihand_ros.bag.messages import KeyframePoseUpdate
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.core.datatypes import FrameResult
import numpy as np
import pytest
from rosbags.typesys.store import Typestore


@pytest.fixture(scope='session')
def typestore() -> Typestore:
    """Return the ROS 2 Jazzy typestore with our types (built once: it generates code)."""
    return build_typestore()


@pytest.fixture
def make_frame(rng: np.random.Generator) -> Callable[..., FrameResult]:
    """Return a builder of random frames drawing from the seeded ``rng``."""
    return lambda frame_index=7: random_frame(rng, frame_index)


@pytest.fixture
def make_keyframes(rng: np.random.Generator) -> Callable[..., KeyframePoseUpdate]:
    """Return a builder of random keyframe updates drawing from the seeded ``rng``."""
    return lambda count=3: random_keyframes(rng, count)
