"""The bounded camera path the node publishes on ``~/camera_path``.

It keeps the newest ``capacity`` poses with their stamps and engine frame indices. When the
engine's pose version changes (a new metric scale or BA corrections), ``refresh`` re-reads the
poses still known to the engine, so the whole published path follows the best trajectory.
``poses_due`` paces publishing: a path of a thousand poses takes tens of milliseconds to build
and serialise, too much to send with every frame of a live camera.
"""

from collections import OrderedDict
from collections.abc import Callable

from infinihand_ros.core.output_fields import PoseFields

#: Looks up the current best pose of an engine frame index, None when no longer known.
PoseLookup = Callable[[int], PoseFields | None]


class CameraPath:
    """Newest-first-out camera poses keyed by frame index (not thread-safe)."""

    def __init__(self, capacity: int) -> None:
        """Start an empty path holding at most ``capacity`` poses."""
        self.capacity = capacity
        self._poses: OrderedDict[int, tuple[int, PoseFields]] = OrderedDict()
        self._version: int | None = None
        self._published_ns: int | None = None  # stamp of the frame the path last went out with
        self._refreshed = False  # poses changed since then

    def __len__(self) -> int:
        """Return the number of poses held."""
        return len(self._poses)

    def add(self, frame_index: int, stamp_ns: int, pose: PoseFields, version: int,
            lookup: PoseLookup | None = None) -> None:
        """Append a frame's pose; with a new ``version``, refresh older poses via ``lookup``."""
        if lookup is not None and self._version is not None and version != self._version:
            self.refresh(lookup)
        self._version = version
        self._poses[frame_index] = (stamp_ns, pose)
        while len(self._poses) > self.capacity:
            self._poses.popitem(last=False)

    def refresh(self, lookup: PoseLookup) -> None:
        """Replace every pose ``lookup`` still knows by its current value."""
        for frame_index, (stamp_ns, pose) in self._poses.items():
            self._poses[frame_index] = (stamp_ns, lookup(frame_index) or pose)
        self._refreshed = True

    def poses_due(self, stamp_ns: int, period_ns: int) -> list[tuple[int, PoseFields]] | None:
        """Return the poses to publish with the frame stamped ``stamp_ns``, or None.

        Due with the first frame, once ``period_ns`` has passed since the last publication
        (image time), and after a refresh (the trajectory changed); ``period_ns`` 0: always.
        """
        last = self._published_ns
        if not (last is None or self._refreshed or stamp_ns - last >= period_ns
                or stamp_ns < last):
            return None
        self._published_ns = stamp_ns
        self._refreshed = False
        return self.poses()

    def poses(self) -> list[tuple[int, PoseFields]]:
        """Return (stamp ns, pose) oldest first."""
        return list(self._poses.values())

    def clear(self) -> None:
        """Forget every pose."""
        self._poses.clear()
        self._version = None
        self._published_ns = None
        self._refreshed = False
