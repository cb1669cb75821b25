"""Binary keyframe pool (paper appendix C): hand-computed selections and properties."""

from hypothesis import given
from hypothesis import settings
from hypothesis import strategies as st
from infinihand_ros.ba.keyframe_pool import BinaryKeyframePool
from infinihand_ros.core.errors import InputError
import pytest

POOL_SIZES = st.tuples(st.integers(min_value=1, max_value=40),
                       st.integers(min_value=2, max_value=6))


def test_hand_computed_selection_toggle_and_prune() -> None:
    """N=4, K=2: select 0, 2, 4; then 0, 4, 6 from [0, 2, 4, 5, 6], retiring 0 and 4."""
    pool = BinaryKeyframePool(trigger=4, stride=2)
    assert [pool.push(i) for i in range(4)] == [None] * 4
    assert pool.push(4) == [0, 2, 4]
    assert [entry.bit for entry in pool.last_selection] == [0, 0, 0]
    assert pool.frame_ids() == [0, 2, 4]
    assert pool.push(5) is None
    assert pool.push(6, state='pose-6') == [0, 4, 6]
    # BA receives the bits before the toggle: 0 and 4 were retained, 6 is new.
    assert [entry.bit for entry in pool.last_selection] == [1, 1, 0]
    assert pool.frame_ids() == [2, 6]
    assert [entry.state for entry in pool.entries()] == [None, 'pose-6']
    assert all(entry.bit == 1 for entry in pool.entries())


def test_window_insert_evaluates_the_trigger_once() -> None:
    """A whole window is inserted before the trigger runs, so one selection covers it."""
    pool = BinaryKeyframePool(trigger=4, stride=3)
    assert pool.extend(range(7), states=[f's{i}' for i in range(7)]) == [0, 3, 6]
    assert pool.frame_ids() == [0, 3, 6]
    assert [entry.state for entry in pool.entries()] == ['s0', 's3', 's6']


def test_bad_arguments_are_refused() -> None:
    """Trigger and stride are checked; ids must be new; states must match the ids."""
    with pytest.raises(InputError, match='trigger N'):
        BinaryKeyframePool(trigger=0, stride=2)
    with pytest.raises(InputError, match='stride K'):
        BinaryKeyframePool(trigger=4, stride=1)
    pool = BinaryKeyframePool(trigger=4, stride=2)
    pool.push(3)
    with pytest.raises(InputError, match=r'\[3\]'):
        pool.push(3)
    with pytest.raises(InputError, match='one state per frame'):
        pool.extend([5, 6], states=['a'])


@settings(max_examples=60, deadline=None)
@given(sizes=POOL_SIZES, windows=st.lists(st.integers(min_value=1, max_value=40), max_size=40))
def test_size_stays_bounded(sizes: tuple[int, int], windows: list[int]) -> None:
    """After any insertion of at most N frames the pool holds at most N entries."""
    trigger, stride = sizes
    pool = BinaryKeyframePool(trigger, stride)
    next_id = 0
    for window in windows:
        window = min(window, trigger)
        pool.extend(range(next_id, next_id + window))
        next_id += window
        assert len(pool) <= trigger


@settings(max_examples=60, deadline=None)
@given(sizes=POOL_SIZES, first=st.integers(min_value=1, max_value=60))
def test_every_frame_is_eventually_retired(sizes: tuple[int, int], first: int) -> None:
    """Frames 0..first-1 all leave the pool, each selected at most twice, within bounded time."""
    trigger, stride = sizes
    pool = BinaryKeyframePool(trigger, stride)
    times_selected = {}
    next_id = 0
    while next_id < first or min(pool.frame_ids(), default=first) < first:
        selection = pool.push(next_id)
        next_id += 1
        for frame_id in selection or []:
            times_selected[frame_id] = times_selected.get(frame_id, 0) + 1
        assert next_id < first + 20 * (trigger + 1) * stride, 'an old frame was never retired'
    assert max(times_selected.values(), default=0) <= 2


@settings(max_examples=60, deadline=None)
@given(sizes=POOL_SIZES, frames=st.integers(min_value=1, max_value=300))
def test_recent_frames_enter_densely(sizes: tuple[int, int], frames: int) -> None:
    """Each selection samples the frames new since the last call at exactly every K-th frame.

    Needs N >= 2K: with a smaller pool the retained entries can fill every selected slot.
    """
    trigger, stride = sizes
    trigger = max(trigger, 2 * stride)
    pool = BinaryKeyframePool(trigger, stride)
    for frame_id in range(frames):
        if pool.push(frame_id) is None:
            continue
        assert all(entry.bit == 1 for entry in pool.entries())
        new_ids = [e.frame_id for e in pool.last_selection if e.bit == 0]
        old_ids = [e.frame_id for e in pool.last_selection if e.bit == 1]
        assert new_ids, 'a selection without any new frame'
        assert all(b - a == stride for a, b in zip(new_ids, new_ids[1:]))
        assert not old_ids or max(old_ids) < min(new_ids)
        # The newest frame is at most K-1 frames past the newest selected one.
        assert frame_id - new_ids[-1] < stride
