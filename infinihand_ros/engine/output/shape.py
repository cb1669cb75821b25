"""One hand shape per side over time: MANO betas averaged over confident detections.

Per-frame betas jitter, and a person's hands do not change shape. ``ShapeConsensus`` averages
the betas of hands at least ``min_confidence`` confident (weighted by confidence); after
``min_samples`` of them the side's shape is fixed and ``reshape_hand`` gives every later hand of
that side this shape. The reshaping changes only the shape part of the joints: the root-relative
joints of the hand model with the shared betas replace those with the frame's betas, with the
wrist, pose and orientation kept, in both the camera and the world frame (the same change,
turned by the rotation between the two frames' orientations). The float64 built-in skeleton is
posed in numpy (``mano/fit.model_joints``), so this costs little per hand.
"""

from dataclasses import replace

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.fit import model_joints
import numpy as np
from scipy.spatial.transform import Rotation


class ShapeConsensus:
    """Confidence-weighted mean betas per side, fixed after enough samples (not thread-safe)."""

    def __init__(self, config: ShapeConfig) -> None:
        """Start with no samples."""
        self.config = config
        self.reset()

    def reset(self) -> None:
        """Forget every sample."""
        self._sums = {side: np.zeros(NUM_BETAS) for side in SIDES}
        self._weights = dict.fromkeys(SIDES, 0.0)
        self._counts = dict.fromkeys(SIDES, 0)

    def observe(self, hand: HandState) -> None:
        """Add a hand's betas if it is confident enough and its side's shape is not fixed."""
        side = hand.side
        if hand.confidence < self.config.min_confidence or self.shared(side) is not None:
            return
        weight = max(hand.confidence, np.finfo(float).tiny)
        self._sums[side] += weight * hand.mano_cam.betas
        self._weights[side] += weight
        self._counts[side] += 1

    def shared(self, side: int) -> np.ndarray | None:
        """Return the side's fixed (10,) betas, or None while it has too few samples."""
        if self._counts[side] < self.config.min_samples:
            return None
        return self._sums[side] / self._weights[side]


def _shape_change(model: HandModel, params: ManoParams, betas: np.ndarray) -> np.ndarray:
    """Return the (21, 3) change of the root-relative joints from the params' to ``betas``."""
    own = model_joints(model, params)
    shared = model_joints(model, replace(params, betas=np.asarray(betas, dtype=np.float64)))
    return (shared - shared[WRIST]) - (own - own[WRIST])


def reshape_hand(hand: HandState, betas: np.ndarray, model: HandModel) -> HandState:
    """Return ``hand`` with shape ``betas``: joints and MANO params in both frames.

    Args:
        hand: a hand with camera-frame (and, if present, world-frame) MANO params and joints.
        betas: (10,) the shape to give it.
        model: the hand model of ``hand.side`` (float64 for the fast path).

    """
    change = _shape_change(model, hand.mano_cam, betas)
    joints_cam = hand.joints_cam + change
    mano_cam = replace(hand.mano_cam, betas=betas)
    if hand.mano_world is None or hand.joints_world is None:
        return replace(hand, joints_cam=joints_cam, mano_cam=mano_cam)
    # Root-relative joints turn with the orientation: world = R_world R_cam^T camera.
    turn = (Rotation.from_rotvec(hand.mano_world.global_orient)
            * Rotation.from_rotvec(hand.mano_cam.global_orient).inv()).as_matrix()
    return replace(hand, joints_cam=joints_cam, mano_cam=mano_cam,
                   joints_world=hand.joints_world + change @ turn.T,
                   mano_world=replace(hand.mano_world, betas=betas))
