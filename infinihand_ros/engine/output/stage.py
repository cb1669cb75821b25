"""The engine's output stage: the last step of every result, whoever consumes it.

The node, the converter and the evaluation all get the engine's results from here, so they
publish and write the same hands. Per result, in order: hand identity per side
(``identity.py``; not for a hand source that keeps its hands' sides over time itself), the
shared shape per side (``shape.py``, when ``shape.enabled``), then smoothing of the
world-frame joints (``smoothing.py``, with ``smoothing.mode: one_euro``).
At a cut between scenes (``new_scene``) hands are not carried over: a hand in the new scene is
not the old scene's hand at the same pixels.
"""

from collections.abc import Sequence
from dataclasses import replace

from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.engine.output.config import OutputConfig
from infinihand_ros.engine.output.identity import HandIdentityTracker
from infinihand_ros.engine.output.shape import reshape_hand
from infinihand_ros.engine.output.shape import ShapeConsensus
from infinihand_ros.engine.output.smoothing import HandSmoother
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.fit import float64_copies


class OutputStage:
    """Identity, shared shape and smoothing of a stream's results (one caller, in order)."""

    def __init__(self, config: OutputConfig, hand_models: Sequence[HandModel],
                 relabel: bool = True) -> None:
        """Start with no tracks, samples or filter state; ``hand_models`` by side (copied).

        ``relabel``: the identity tracker may change a hand's side (False where the hand
        source decides sides over time itself).
        """
        self.config = config
        self.relabel = relabel
        self.hand_models = float64_copies(hand_models)  # posed in numpy by ``reshape_hand``
        self.identity = HandIdentityTracker(config.identity)
        self.shape = ShapeConsensus(config.shape)
        self.smoother = HandSmoother(config.smoothing)

    def apply(self, result: FrameResult) -> FrameResult:
        """Return ``result`` with its hands given identity, shared shape and smoothing."""
        size = (result.intrinsics.width, result.intrinsics.height)
        hands = (self.identity.assign(result.hands, result.timestamp_ns, size) if self.relabel
                 else result.hands)
        if self.config.shape.enabled:
            hands = tuple(self._shared_shape(hand) for hand in hands)
        hands = self.smoother.apply(hands, result.timestamp_ns)
        return replace(result, hands=hands)

    def new_scene(self) -> None:
        """Forget hand tracks and filter state at a cut (the shared shape is kept)."""
        self.identity.reset()
        self.smoother.reset()

    def reset(self) -> None:
        """Start a new stream: forget tracks, shape samples and filter state."""
        self.identity.reset()
        self.shape.reset()
        self.smoother.reset()

    def _shared_shape(self, hand: HandState) -> HandState:
        """Feed the shape consensus; give the hand its side's shared shape once there is one."""
        self.shape.observe(hand)
        betas = self.shape.shared(hand.side)
        if betas is None:
            return hand
        return reshape_hand(hand, betas, self.hand_models[hand.side])
