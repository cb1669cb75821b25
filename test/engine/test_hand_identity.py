"""Per-side hand identity over time (engine/output/identity.py)."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.output.config import IdentityConfig
from infinihand_ros.engine.output.identity import HandIdentityTracker
from result_builders import make_hand

SIZE = (640, 480)  # diagonal 800 px: radius 0.25 -> 200 px
MS = 1_000_000


def sides(hands: tuple) -> list[tuple[int, float]]:
    """Return (side, wrist x) of each hand."""
    return [(hand.side, float(hand.joints_2d[0, 0])) for hand in hands]


def test_swapped_labels_are_swapped_back() -> None:
    """Two hands whose labels flip between frames keep their sides."""
    tracker = HandIdentityTracker(IdentityConfig())
    tracker.assign((make_hand(LEFT, (100, 200)), make_hand(RIGHT, (500, 200))), 0, SIZE)
    flipped = (make_hand(RIGHT, (104, 200)), make_hand(LEFT, (497, 200)))
    assert sides(tracker.assign(flipped, 33 * MS, SIZE)) == [(LEFT, 104.0), (RIGHT, 497.0)]
    assert tracker.relabelled == 2


def test_single_hand_flip_is_undone_and_new_hand_keeps_its_label() -> None:
    """A lone hand relabelled near the other side's track is restored; a far one is new."""
    tracker = HandIdentityTracker(IdentityConfig())
    tracker.assign((make_hand(LEFT, (100, 200)),), 0, SIZE)
    assert sides(tracker.assign((make_hand(RIGHT, (103, 200)),), 33 * MS, SIZE)) == [
        (LEFT, 103.0)]
    assert sides(tracker.assign((make_hand(LEFT, (106, 200)), make_hand(RIGHT, (520, 200))),
                                66 * MS, SIZE)) == [(LEFT, 106.0), (RIGHT, 520.0)]


def test_fast_hand_keeps_a_consistent_label() -> None:
    """A hand that jumps beyond the radius but keeps its label is not relabelled."""
    tracker = HandIdentityTracker(IdentityConfig())
    tracker.assign((make_hand(LEFT, (100, 200)),), 0, SIZE)
    assert sides(tracker.assign((make_hand(LEFT, (400, 200)),), 33 * MS, SIZE)) == [
        (LEFT, 400.0)]


def test_stale_track_is_forgotten_so_the_model_label_wins() -> None:
    """After max_gap_s without the hand, a hand at its old place takes the model's label."""
    tracker = HandIdentityTracker(IdentityConfig(max_gap_s=0.5))
    tracker.assign((make_hand(LEFT, (100, 200)),), 0, SIZE)
    assert sides(tracker.assign((make_hand(RIGHT, (100, 200)),), 600 * MS, SIZE)) == [
        (RIGHT, 100.0)]
    assert tracker.relabelled == 0


def test_no_hands_gives_no_hands() -> None:
    """An empty frame stays empty (no phantom hands)."""
    tracker = HandIdentityTracker(IdentityConfig())
    tracker.assign((make_hand(LEFT, (100, 200)),), 0, SIZE)
    assert tracker.assign((), 33 * MS, SIZE) == ()
