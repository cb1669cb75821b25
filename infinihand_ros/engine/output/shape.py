"""One hand shape per side over time: MANO betas averaged over confident detections.

Per-frame betas jitter, and a person's hands do not change shape. ``ShapeConsensus`` averages
the betas of hands at least ``min_confidence`` confident (weighted by confidence); after
``min_samples`` of them the side's shape is fixed and ``reshape_hand`` gives every later hand of
that side this shape. The reshaping changes only the shape part of the joints: the root-relative
joints of the hand model with the shared betas replace those with the frame's betas, with the
wrist, pose and orientation kept, in both the camera and the world frame.
"""

from dataclasses import replace

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.mano.base import HandModel
import numpy as np
import torch


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


def _root_relative(model: HandModel, params: ManoParams, betas: np.ndarray) -> np.ndarray:
    """Return (2, 21, 3) joints minus the wrist for the params' betas and for ``betas``."""
    def batch(value: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.stack([value, value]), dtype=torch.float64)

    with torch.inference_mode():
        joints = model(batch(params.global_orient), batch(params.hand_pose),
                       torch.as_tensor(np.stack([params.betas, betas]), dtype=torch.float64),
                       batch(params.transl)).joints.to(torch.float64).cpu().numpy()
    return joints - joints[:, WRIST:WRIST + 1]


def reshape_hand(hand: HandState, betas: np.ndarray, model: HandModel) -> HandState:
    """Return ``hand`` with shape ``betas``: joints and MANO params in both frames.

    Args:
        hand: a hand with camera-frame (and, if present, world-frame) MANO params and joints.
        betas: (10,) the shape to give it.
        model: the hand model of ``hand.side`` (the engine's).

    """
    own, shared = _root_relative(model, hand.mano_cam, betas)
    joints_cam = hand.joints_cam + (shared - own)
    mano_cam = replace(hand.mano_cam, betas=betas)
    if hand.mano_world is None or hand.joints_world is None:
        return replace(hand, joints_cam=joints_cam, mano_cam=mano_cam)
    own, shared = _root_relative(model, hand.mano_world, betas)
    return replace(hand, joints_cam=joints_cam, mano_cam=mano_cam,
                   joints_world=hand.joints_world + (shared - own),
                   mano_world=replace(hand.mano_world, betas=betas))
