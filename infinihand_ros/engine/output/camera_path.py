"""The bounded camera path the node publishes on ``~/camera_path``.

It keeps the newest ``capacity`` poses with their stamps and engine frame indices. When the
engine's pose version changes (a new metric scale or BA corrections), the poses still known to
the engine are re-read before the path next goes out, so the whole published path follows the
best trajectory. ``poses_due`` paces publishing (and with it that re-reading): a path of a
thousand poses takes tens of milliseconds to re-read, build and serialise, too much for every
frame of a live camera, and the scale may change on every third one.
"""

from collections import OrderedDict
from collections.abc import Callable

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.output_fields import PoseFields

#: Looks up the current best pose of an engine frame index, None when no longer known.
PoseLookup = Callable[[int], CameraPose | None]


class CameraPath:
    """Newest-first-out camera poses keyed by frame index (not thread-safe)."""

    def __init__(self, capacity: int) -> None:
        """Start an empty path holding at most ``capacity`` poses."""
        self.capacity = capacity
        self._poses: OrderedDict[int, tuple[int, PoseFields]] = OrderedDict()
        self._version: int | None = None
        self._published_ns: int | None = None  # stamp of the frame the path last went out with
        self._stale: PoseLookup | None = None  # re-reads poses of an older version when set

    def __len__(self) -> int:
        """Return the number of poses held."""
        return len(self._poses)

    def add(self, frame_index: int, stamp_ns: int, pose: PoseFields, version: int,
            lookup: PoseLookup | None = None) -> None:
        """Append a frame's pose; a new ``version`` marks older poses to re-read via ``lookup``.

        They are re-read when the path is next due (``poses_due``), not here.
        """
        if lookup is not None and self._version is not None and version != self._version:
            self._stale = lookup
        self._version = version
        self._poses[frame_index] = (stamp_ns, pose)
        while len(self._poses) > self.capacity:
            self._poses.popitem(last=False)

    def refresh(self, lookup: PoseLookup) -> None:
        """Replace every pose ``lookup`` still knows by its current value (one conversion)."""
        found = [(index, pose) for index in self._poses
                 if (pose := lookup(index)) is not None]
        converted = PoseFields.from_camera_poses([pose for _, pose in found])
        for (index, _), fields in zip(found, converted):
            self._poses[index] = (self._poses[index][0], fields)
        self._stale = None

    def poses_due(self, stamp_ns: int, period_ns: int) -> list[tuple[int, PoseFields]] | None:
        """Return the poses to publish with the frame stamped ``stamp_ns``, or None.

        Due with the first frame and once ``period_ns`` has passed since the last publication
        (image time); ``period_ns`` 0: always. Poses of an older version are re-read first, so
        a refined trajectory goes out with the next due publication.
        """
        last = self._published_ns
        if not (last is None or stamp_ns - last >= period_ns or stamp_ns < last):
            return None
        if self._stale is not None:
            self.refresh(self._stale)
        self._published_ns = stamp_ns
        return self.poses()

    def poses(self) -> list[tuple[int, PoseFields]]:
        """Return (stamp ns, pose) oldest first."""
        return list(self._poses.values())

    def clear(self) -> None:
        """Forget every pose."""
        self._poses.clear()
        self._version = None
        self._published_ns = None
        self._stale = None
