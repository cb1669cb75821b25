"""Per-side hand identity over time: at most one left and one right, no flips between frames.

The model labels each hand left or right per frame, and such labels flip now and then (a hand
seen edge-on). Each side keeps a track: its wrist's last image position and stamp. A frame's
hands (at most one per side, ``FrameResult`` guarantees it) are assigned to sides by the lowest
total cost over the possible assignments:

- a side whose live track is within ``match_radius`` (fraction of the image diagonal) of the
  hand costs the distance as a fraction of that radius (0..1);
- a side with no live track, or whose track is farther, costs 1 (a new track);
- taking the side the model did not say adds ``LABEL_PRIOR``.

The model's labelling is kept unless another assignment costs strictly less. Tracks unseen for
more than ``max_gap_s`` are forgotten (a hand coming back takes the model's label).
"""

from dataclasses import dataclass
from dataclasses import replace
import itertools
import math
from typing import Final

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.output.config import IdentityConfig
import numpy as np

#: Cost of giving a hand the side the model did not predict (half a track radius).
LABEL_PRIOR: Final = 0.5
#: Cost of starting a new track.
NEW_TRACK_COST: Final = 1.0


@dataclass(frozen=True)
class _Track:
    wrist_px: np.ndarray
    stamp_ns: int


class HandIdentityTracker:
    """Keeps each side's identity from frame to frame (not thread-safe)."""

    def __init__(self, config: IdentityConfig) -> None:
        """Start with no tracks."""
        self.config = config
        self._tracks: dict[int, _Track] = {}
        self.relabelled = 0

    def reset(self) -> None:
        """Forget every track."""
        self._tracks.clear()

    def assign(self, hands: tuple[HandState, ...], stamp_ns: int,
               image_size: tuple[int, int]) -> tuple[HandState, ...]:
        """Return the frame's hands with their sides kept consistent with the tracks.

        Args:
            hands: at most one hand per side, as the engine labelled them.
            stamp_ns: the frame's stamp, nanoseconds.
            image_size: (width, height) of the image ``joints_2d`` are in, pixels.

        Returns:
            The same hands (sides possibly exchanged), at most one per side, sorted by side.

        """
        self._forget_stale(stamp_ns)
        radius_px = self.config.match_radius * math.hypot(*image_size)
        labelled = tuple(hand.side for hand in hands)
        best_sides, best_cost = labelled, self._cost(hands, labelled, radius_px)
        for sides in itertools.permutations(SIDES, len(hands)):
            cost = self._cost(hands, sides, radius_px)
            if cost < best_cost:
                best_sides, best_cost = sides, cost
        out = []
        for hand, side in zip(hands, best_sides):
            if side != hand.side:
                self.relabelled += 1
                hand = replace(hand, side=side)
            self._tracks[side] = _Track(np.array(hand.joints_2d[WRIST], dtype=np.float64),
                                        stamp_ns)
            out.append(hand)
        return tuple(sorted(out, key=lambda hand: hand.side))

    def _forget_stale(self, stamp_ns: int) -> None:
        """Drop tracks last seen more than ``max_gap_s`` before ``stamp_ns``."""
        limit = self.config.max_gap_s * NS_PER_S
        for side in [side for side, track in self._tracks.items()
                     if stamp_ns - track.stamp_ns > limit]:
            del self._tracks[side]

    def _cost(self, hands: tuple[HandState, ...], sides: tuple[int, ...],
              radius_px: float) -> float:
        """Return the cost of giving ``hands`` the ``sides`` (see the module docstring)."""
        total = 0.0
        for hand, side in zip(hands, sides):
            track = self._tracks.get(side)
            distance = (math.inf if track is None
                        else float(np.linalg.norm(hand.joints_2d[WRIST] - track.wrist_px)))
            total += distance / radius_px if distance <= radius_px else NEW_TRACK_COST
            total += LABEL_PRIOR if side != hand.side else 0.0
        return total
