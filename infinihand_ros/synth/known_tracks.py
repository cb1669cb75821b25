"""Hand tracks with known built-in-hand parameters, for checking fits and cleaning.

A track moves smoothly between a few keyframes, each a gesture of the synthetic generator
(``gestures.py``), a random orientation and a position 0.3-0.6 m in front of the camera
(OpenCV optical frame). The joints come from the built-in hand, so the parameters are exact.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.synth import gestures
import numpy as np
from scipy.spatial.transform import Rotation
from scipy.spatial.transform import Slerp
import torch

#: Gestures the keyframes draw from (the generator's grasp and hover kinds).
TRACK_GESTURES: Final = ('open', 'power', 'pinch', 'point', 'fist', 'tripod', 'relaxed')
#: Box (camera frame, m) the keyframe wrist positions are drawn in.
POSITION_RANGE_M: Final = ((-0.15, -0.1, 0.3), (0.15, 0.1, 0.6))
#: Standard deviation of the keyframe orientations (axis-angle, rad) and of the betas.
ORIENTATION_SIGMA_RAD: Final = 1.2
BETA_SIGMA: Final = 0.8


@dataclass(frozen=True)
class KnownTrack:
    """A camera-frame hand track and the parameters that made it (T frames, float64).

    Attributes:
        side: 0 left, 1 right.
        global_orient: (T, 3) axis-angle.
        hand_pose: (T, 15, 3) axis-angle, flat-hand relative.
        betas: (10,) shape.
        transl: (T, 3) metres.
        joints: (T, 21, 3) built-in hand joints, metres, OpenPose order.

    """

    side: int
    global_orient: np.ndarray
    hand_pose: np.ndarray
    betas: np.ndarray
    transl: np.ndarray
    joints: np.ndarray


def known_track(rng: np.random.Generator, side: int, frames: int,
                keyframes: int = 3) -> KnownTrack:
    """Draw a track of ``frames`` frames through ``keyframes`` keyframes (at least 2)."""
    times = np.linspace(0.0, 1.0, keyframes)
    tau = np.linspace(0.0, 1.0, frames)
    kinds = rng.integers(len(TRACK_GESTURES), size=keyframes)
    vectors = np.stack([gestures.draw_gesture(rng, TRACK_GESTURES[k]).as_vector()
                        for k in kinds])
    path = np.stack([np.interp(tau, times, column) for column in vectors.T], axis=1)
    hand_pose = gestures.gesture_hand_pose(path, side)
    rotations = Rotation.from_rotvec(rng.normal(scale=ORIENTATION_SIGMA_RAD,
                                                size=(keyframes, 3)))
    orient = Slerp(times, rotations)(tau).as_rotvec()
    positions = rng.uniform(*POSITION_RANGE_M, size=(keyframes, 3))
    transl = np.stack([np.interp(tau, times, column) for column in positions.T], axis=1)
    betas = np.clip(rng.normal(scale=BETA_SIGMA, size=NUM_BETAS), -2.0, 2.0)
    model = BuiltinHandModel(side, dtype=torch.float64)
    with torch.no_grad():
        joints = model(torch.as_tensor(orient), torch.as_tensor(hand_pose),
                       torch.as_tensor(np.tile(betas, (frames, 1))),
                       torch.as_tensor(transl)).joints.numpy()
    return KnownTrack(side, orient, hand_pose, betas, transl, joints)
