"""Smoothing of the teleop outputs: a One-Euro filter per side on the world-frame joints.

The wrist pose and the wrist-frame landmarks are derived from the smoothed joints, so every
hand output stays consistent. A side's filter restarts when its hand is not seen in a frame (no
smoothing across a gap, nothing stale). With ``mode: none`` the hands pass unchanged.
"""

from dataclasses import replace

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.engine.output.one_euro import OneEuroFilter


class HandSmoother:
    """One One-Euro filter per side (not thread-safe)."""

    def __init__(self, config: SmoothingConfig) -> None:
        """Build the filters of ``config`` (none when ``mode`` is 'none')."""
        self.enabled = config.mode == 'one_euro'
        self._filters = {side: OneEuroFilter(config.min_cutoff_hz, config.beta,
                                             config.d_cutoff_hz) for side in SIDES}

    def reset(self) -> None:
        """Restart every filter."""
        for one_euro in self._filters.values():
            one_euro.reset()

    def apply(self, hands: tuple[HandState, ...], stamp_ns: int) -> tuple[HandState, ...]:
        """Return the hands with smoothed ``joints_world`` (hands without them pass as they are).

        Args:
            hands: at most one hand per side.
            stamp_ns: the frame's stamp, nanoseconds (the filters' time).

        """
        if not self.enabled:
            return hands
        seen = {hand.side for hand in hands if hand.joints_world is not None}
        for side in set(SIDES) - seen:
            self._filters[side].reset()
        return tuple(
            hand if hand.joints_world is None else replace(
                hand, joints_world=self._filters[hand.side](hand.joints_world,
                                                            stamp_ns / NS_PER_S))
            for hand in hands)
