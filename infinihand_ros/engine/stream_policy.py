"""A stream's stamp order and restarts: what a frame whose stamp does not increase means.

Within a stream stamps increase (``engine/timestamps.py``). A frame stamped not after the last
accepted one is out of order (late or repeated): it is refused and counted, the stream goes
on. One stamped more than ``restart_after_s`` before it (a replay looping, a camera driver
restarting, normal stamps after a far-future one) starts a new stream: the engine resets (a new
world frame, pose track and BA) and the frame is the new stream's first. The engine owns one
``StreamPolicy`` and applies it in ``push``; a caller can ask first (``StreamingEngine.
stamp_step``) to reset what it keeps per stream before it pushes.
"""

from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.timestamps import check_timestamp
from infinihand_ros.engine.timestamps import stamp_step
from infinihand_ros.engine.timestamps import StampStep


class StreamPolicy:
    """The last accepted stamp of a stream and what the next stamp means (with counts)."""

    def __init__(self, restart_after_s: float) -> None:
        """Start before a stream's first frame.

        Args:
            restart_after_s: a stamp earlier than the last accepted one by more than this
                starts a new stream, s; 0: never (every stamp not after it is out of order).

        """
        self.restart_after_ns = int(restart_after_s * NS_PER_S)
        self.last_ns: int | None = None  # stamp of the last accepted frame, ns
        self.out_of_order = 0  # frames refused as out of order, since start
        self.restarts = 0  # frames that started a new stream, since start

    def step(self, stamp_ns: int) -> StampStep:
        """Return how a frame stamped ``stamp_ns`` follows the last accepted one (no change)."""
        return stamp_step(stamp_ns, self.last_ns, self.restart_after_ns)

    def admit(self, stamp_ns: int) -> StampStep:
        """Check a frame's stamp (an int64 integer); return ``NEXT`` or ``RESTART`` (counted).

        Raises:
            InputError: for a stamp out of order (counted in ``out_of_order``; the message
                names both stamps and says which way it is out of order).

        """
        step = self.step(stamp_ns)
        if step is StampStep.OUT_OF_ORDER:
            self.out_of_order += 1
            check_timestamp(stamp_ns, self.last_ns)  # raises
        if step is StampStep.RESTART:
            self.restarts += 1
        return step

    def accept(self, stamp_ns: int | None) -> None:
        """Take ``stamp_ns`` as the stream's last accepted stamp (None: a new stream's start)."""
        self.last_ns = stamp_ns
