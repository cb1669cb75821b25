"""Builders shared by the evaluation tests: a pinhole camera and hands in front of it."""

from collections.abc import Callable

from infinihand_ros.core.hand_conventions import NUM_JOINTS
import numpy as np
import pytest

#: Test camera: fx = fy = 500 px, principal point (320, 240), 640 x 480 image (diagonal 800 px).
FOCAL_PX = 500.0
WIDTH, HEIGHT = 640, 480
HAND_DEPTH_M = 0.5


@pytest.fixture
def intrinsics() -> np.ndarray:
    """Return the test camera's K."""
    return np.array([[FOCAL_PX, 0.0, WIDTH / 2], [0.0, FOCAL_PX, HEIGHT / 2], [0.0, 0.0, 1.0]])


@pytest.fixture
def flat_hand() -> Callable[..., np.ndarray]:
    """Return a builder of a planar hand (21, 3): wrist at ``wrist``, other joints within 4 cm.

    All joints share the wrist's depth, so a lateral offset of d metres at 0.5 m depth moves every
    projected joint by exactly 500 * d / 0.5 = 1000 d pixels.
    """
    offsets = np.random.default_rng(7).uniform(-0.04, 0.04, size=(NUM_JOINTS, 3))
    offsets[:, 2] = 0.0
    offsets[0] = 0.0

    def build(wrist: np.ndarray | None = None) -> np.ndarray:
        if wrist is None:
            wrist = np.array([0.0, 0.0, HAND_DEPTH_M])
        return np.asarray(wrist, dtype=np.float64) + offsets

    return build


@pytest.fixture(scope='session')
def solid_hand() -> np.ndarray:
    """Return a read-only non-planar hand (21, 3) in metres around (0, 0, 0.5)."""
    joints = np.random.default_rng(11).normal(scale=0.03, size=(NUM_JOINTS, 3))
    joints += np.array([0.0, 0.0, HAND_DEPTH_M])
    joints.setflags(write=False)  # shared by every test (and hypothesis example): never mutated
    return joints
