"""The latest-frame mailbox (core/latest_frame.py)."""

import threading

from infinihand_ros.core.latest_frame import LatestFrameSlot


def test_newest_wins_and_drops_are_counted() -> None:
    """Two puts before a take: the second is taken, one drop counted."""
    slot: LatestFrameSlot[int] = LatestFrameSlot()
    assert slot.put(1) is False
    assert slot.put(2) is True
    assert slot.take(0.0) == 2
    assert slot.take(0.0) is None
    assert slot.dropped == 1


def test_take_waits_for_a_put_and_close_wakes_it() -> None:
    """A waiting take gets an item put from another thread; close ends waiting."""
    slot: LatestFrameSlot[str] = LatestFrameSlot()
    got: list = []
    taker = threading.Thread(target=lambda: got.append(slot.take(5.0)))
    taker.start()
    slot.put('frame')
    taker.join(5.0)
    assert got == ['frame']
    waiter = threading.Thread(target=lambda: got.append(slot.take(30.0)))
    waiter.start()
    slot.close()
    waiter.join(5.0)
    assert not waiter.is_alive() and got == ['frame', None] and slot.closed
