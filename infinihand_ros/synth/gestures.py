"""Finger articulation of the synthetic hands: a library of gestures and their MANO pose.

A gesture is a set of joint angles in degrees: flexion of the three joints of each finger, the
spread (abduction) of each finger at its base, and the thumb's opposition at its base. Keyframes
draw a gesture by kind (power grasps of different object sizes, pinches, a tripod grip, pointing,
an open or relaxed hand, a fist, or independent random fingers) with per-finger variation; the
motion interpolates the angles between keyframes, and ``gesture_hand_pose`` turns them into MANO
``hand_pose`` axis-angles of the built-in hand (right hand canonical frame, mirrored for the left).
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.mano.mirror import mirror_axis_angle
import numpy as np
from scipy.spatial.transform import Rotation

#: Fingers in anatomical order; MANO's hand_pose order is index, middle, pinky, ring, thumb.
FINGERS: Final = ('thumb', 'index', 'middle', 'ring', 'pinky')
#: Position of each anatomical finger in MANO's hand_pose order (three joints each).
MANO_FINGER_SLOT: Final = {'index': 0, 'middle': 1, 'pinky': 2, 'ring': 3, 'thumb': 4}
#: Flexion axis of the long fingers and of the thumb in the right hand's canonical frame
#: (fingers along -x, palm facing -y, thumb towards +z: flexion turns -x towards -y).
FINGER_FLEX_AXIS: Final = np.array([0.0, 0.0, 1.0])
THUMB_FLEX_AXIS: Final = np.array([0.64, 0.0, 0.77]) / np.linalg.norm([0.64, 0.0, 0.77])
#: Spread axis (the palm normal): a positive angle turns a finger towards the thumb.
SPREAD_AXIS: Final = np.array([0.0, 1.0, 0.0])
#: Opposition axis of the thumb's base: a positive angle turns the thumb across the palm.
OPPOSITION_AXIS: Final = np.array([1.0, 0.0, 0.0])
#: Spread direction per long finger when the hand opens (index towards the thumb, pinky away).
SPREAD_SIGN: Final = {'index': 1.0, 'middle': 0.2, 'ring': -0.7, 'pinky': -1.4}
#: Per-joint flexion noise (degrees, 1 sigma) added to every drawn gesture.
FLEX_JITTER_DEG: Final = 6.0
#: Gesture kinds drawn for a reach to the table and for a hand held in view, with probabilities.
GRASP_KINDS: Final = {'power': 0.45, 'pinch': 0.3, 'tripod': 0.25}
HOVER_KINDS: Final = {'open': 0.2, 'relaxed': 0.1, 'point': 0.2, 'pinch': 0.1, 'fist': 0.15,
                      'random': 0.25}
#: Largest flexion (degrees) of the proximal, middle and distal joints of a long finger.
MAX_FLEX_DEG: Final = (85.0, 100.0, 65.0)
#: Largest flexion (degrees) of the thumb's three joints.
MAX_THUMB_FLEX_DEG: Final = (40.0, 50.0, 60.0)


@dataclass(frozen=True)
class Gesture:
    """Joint angles of one hand (degrees).

    Attributes:
        flex: (5, 3) flexion per finger (anatomical order) and joint (base, middle, tip).
        spread: (5,) abduction of each finger at its base (the thumb's is unused).
        opposition: thumb opposition at its base.

    """

    flex: np.ndarray
    spread: np.ndarray
    opposition: float

    def as_vector(self) -> np.ndarray:
        """Flatten to (21,) for interpolation: 15 flexions, 5 spreads, the opposition."""
        return np.concatenate([self.flex.ravel(), self.spread, [self.opposition]])

    @staticmethod
    def from_vector(vector: np.ndarray) -> 'Gesture':
        """Inverse of ``as_vector``."""
        return Gesture(flex=vector[:15].reshape(5, 3), spread=vector[15:20],
                       opposition=float(vector[20]))


def _long_flex(level: float) -> np.ndarray:
    """Flexion of one long finger's three joints at ``level`` in [0, 1] of the maximum."""
    return level * np.array(MAX_FLEX_DEG)


def _thumb_flex(level: float) -> np.ndarray:
    """Flexion of the thumb's three joints at ``level`` in [0, 1] of the maximum."""
    return level * np.array(MAX_THUMB_FLEX_DEG)


def _spread(amount_deg: float) -> np.ndarray:
    """Spread angles (thumb first) of an opened hand whose index spreads by ``amount_deg``."""
    return np.array([0.0] + [SPREAD_SIGN[f] * amount_deg for f in FINGERS[1:]])


def draw_gesture(rng: np.random.Generator, kind: str) -> Gesture:
    """Draw a gesture of ``kind`` (see ``GRASP_KINDS`` and ``HOVER_KINDS``, plus ``rest``)."""
    flex = np.zeros((5, 3))
    opposition = 0.0
    spread = _spread(rng.uniform(0.0, 6.0))
    if kind == 'power':
        closure = rng.uniform(0.25, 1.0)  # small objects close the hand further
        for i in range(1, 5):
            flex[i] = _long_flex(closure + rng.uniform(-0.08, 0.08))
        flex[0] = _thumb_flex(closure * rng.uniform(0.6, 1.0))
        opposition = rng.uniform(25.0, 55.0)
    elif kind in ('pinch', 'tripod'):
        tip = rng.uniform(0.4, 0.7)
        flex[1] = _long_flex(tip)
        if kind == 'tripod':
            flex[2] = _long_flex(tip + rng.uniform(-0.05, 0.1))
        others = rng.uniform(0.05, 0.85)  # remaining fingers extended or tucked in
        for i in range(3 if kind == 'tripod' else 2, 5):
            flex[i] = _long_flex(others + rng.uniform(-0.1, 0.1))
        flex[0] = _thumb_flex(rng.uniform(0.4, 0.8))
        opposition = rng.uniform(40.0, 65.0)
    elif kind == 'point':
        flex[1] = _long_flex(rng.uniform(0.0, 0.12))
        for i in range(2, 5):
            flex[i] = _long_flex(rng.uniform(0.7, 1.0))
        flex[0] = _thumb_flex(rng.uniform(0.3, 0.9))
        opposition = rng.uniform(10.0, 45.0)
    elif kind == 'fist':
        for i in range(1, 5):
            flex[i] = _long_flex(rng.uniform(0.8, 1.0))
        flex[0] = _thumb_flex(rng.uniform(0.5, 1.0))
        opposition = rng.uniform(20.0, 50.0)
    elif kind == 'open':
        for i in range(1, 5):
            flex[i] = _long_flex(rng.uniform(0.0, 0.1))
        flex[0] = _thumb_flex(rng.uniform(0.0, 0.15))
        spread = _spread(rng.uniform(5.0, 20.0))
        opposition = rng.uniform(-5.0, 10.0)
    elif kind in ('relaxed', 'rest'):
        for i in range(1, 5):
            flex[i] = _long_flex(rng.uniform(0.15, 0.4) + 0.05 * i)
        flex[0] = _thumb_flex(rng.uniform(0.1, 0.4))
        opposition = rng.uniform(5.0, 25.0)
    elif kind == 'random':
        flex[1:] = rng.uniform(0.0, 1.0, size=(4, 1)) * np.array(MAX_FLEX_DEG)[None]
        flex[0] = _thumb_flex(rng.uniform(0.0, 1.0))
        spread = _spread(rng.uniform(-2.0, 14.0)) + rng.normal(scale=3.0, size=5)
        opposition = rng.uniform(-5.0, 60.0)
    else:
        raise ValueError(f'unknown gesture kind {kind!r}')
    flex = np.clip(flex + rng.normal(scale=FLEX_JITTER_DEG, size=flex.shape), -5.0, None)
    return Gesture(flex=flex, spread=spread, opposition=opposition)


def draw_kind(rng: np.random.Generator, kinds: dict[str, float]) -> str:
    """Draw a gesture kind from a ``{kind: probability}`` table."""
    names = list(kinds)
    return names[rng.choice(len(names), p=list(kinds.values()))]


def gesture_hand_pose(vectors: np.ndarray, side: int) -> np.ndarray:
    """Return MANO hand poses (T, 15, 3) of gesture vectors (T, 21) for ``side``.

    The vectors are ``Gesture.as_vector`` layouts, e.g. interpolated between keyframes.
    """
    vectors = np.asarray(vectors, dtype=np.float64)
    num = len(vectors)
    pose = np.zeros((num, NUM_HAND_POSE_JOINTS, 3))
    for finger_index, finger in enumerate(FINGERS):
        slot = MANO_FINGER_SLOT[finger]
        axis = THUMB_FLEX_AXIS if finger == 'thumb' else FINGER_FLEX_AXIS
        for joint in range(3):
            angle = np.radians(vectors[:, finger_index * 3 + joint])
            rotation = Rotation.from_rotvec(angle[:, None] * axis[None])
            if joint == 0:
                if finger == 'thumb':
                    base = np.radians(vectors[:, 20])[:, None] * OPPOSITION_AXIS[None]
                else:
                    base = np.radians(vectors[:, 15 + finger_index])[:, None] * SPREAD_AXIS[None]
                rotation = Rotation.from_rotvec(base) * rotation
            pose[:, slot * 3 + joint] = rotation.as_rotvec()
    return mirror_axis_angle(pose) if side == LEFT else pose
