"""Which hand is which (engine/hands/side.py): label, arm entry, history, one per side."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import MIDDLE_MCP
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.engine.hands.side import arm_entry
from infinihand_ros.engine.hands.side import label_log_odds
from infinihand_ros.engine.hands.side import SideTracker
import numpy as np
import pytest

WIDTH, HEIGHT = 640, 480


def _hand(side: int, wrist: tuple[float, float], fingers: tuple[float, float],
          score: float = 0.9) -> Detection2D:
    """Return a hand whose joints run from ``wrist`` along ``fingers`` (a pixel direction)."""
    along = np.asarray(fingers, dtype=np.float64) / np.hypot(*fingers)
    across = np.array([-along[1], along[0]])
    steps = np.linspace(0.0, 80.0, 21)
    pixels = wrist + steps[:, None] * along + (np.arange(21) % 5 - 2)[:, None] * 6.0 * across
    pixels[WRIST] = wrist
    pixels[MIDDLE_MCP] = np.asarray(wrist) + 40.0 * along
    return Detection2D(side, pixels, np.full(21, score), score, np.zeros((21, 3)))


@pytest.mark.parametrize('wrist, fingers, expected', [
    ((500.0, 400.0), (-0.3, -1.0), 1.0),   # forearm down and right: the lower right
    ((150.0, 420.0), (0.2, -1.0), -1.0),   # forearm down and left: the lower left
    ((600.0, 150.0), (-1.0, -0.2), 1.0),   # forearm to the right border
    ((40.0, 200.0), (1.0, 0.1), -1.0),     # forearm to the left border
    ((320.0, 100.0), (0.0, 1.0), 0.0),     # forearm up: through the top, not the wearer's
])
def test_the_arm_enters_where_the_forearm_leaves_the_image(wrist: tuple, fingers: tuple,
                                                           expected: float) -> None:
    """The wrist's ray away from the middle knuckle names the border the arm comes through."""
    assert arm_entry(_hand(RIGHT, wrist, fingers).joints_2d, WIDTH, HEIGHT) == expected


def test_an_arm_through_the_bottom_centre_is_weak_evidence() -> None:
    """Leaving the bottom near its centre says little; the same hand mirrored says the opposite."""
    hand = _hand(RIGHT, (340.0, 420.0), (0.0, -1.0))
    evidence = arm_entry(hand.joints_2d, WIDTH, HEIGHT)
    assert 0.0 < evidence < 0.2
    mirrored = hand.joints_2d * [-1.0, 1.0] + [WIDTH, 0.0]
    assert arm_entry(mirrored, WIDTH, HEIGHT) == pytest.approx(-evidence)
    assert arm_entry(np.zeros((21, 2)), WIDTH, HEIGHT) == 0.0


def test_label_log_odds_are_signed_by_side_and_zero_when_unsure() -> None:
    """0.5 says nothing; 0.9 is log 9 toward its side; 1.0 stays finite."""
    assert label_log_odds(RIGHT, 0.5) == 0.0
    assert label_log_odds(LEFT, 0.9) == pytest.approx(-np.log(9.0))
    assert np.isfinite(label_log_odds(RIGHT, 1.0))


def test_a_head_mounted_arm_decides_an_unsure_label_but_not_a_sure_one() -> None:
    """Egocentric: an arm from the lower right turns an unsure 'left' right; a sure one stays."""
    unsure = _hand(LEFT, (500.0, 400.0), (-0.3, -1.0), score=0.7)
    decision = SideTracker(egocentric=True).decide([unsure], WIDTH, HEIGHT)
    assert [hand.side for hand in decision.hands] == [RIGHT] and decision.relabelled == 1
    sure = _hand(LEFT, (500.0, 400.0), (-0.3, -1.0), score=0.97)
    assert [h.side for h in SideTracker(True).decide([sure], WIDTH, HEIGHT).hands] == [LEFT]


def test_a_third_person_view_keeps_mediapipes_label() -> None:
    """Not egocentric (teleop): the arm's side of entry is not evidence."""
    unsure = _hand(LEFT, (500.0, 400.0), (-0.3, -1.0), score=0.6)
    decision = SideTracker(egocentric=False).decide([unsure], WIDTH, HEIGHT)
    assert [hand.side for hand in decision.hands] == [LEFT] and decision.relabelled == 0


def test_mirrored_images_swap_the_arms_evidence() -> None:
    """In a selfie view the wearer's right arm comes from the lower left."""
    unsure = _hand(LEFT, (500.0, 400.0), (-0.3, -1.0), score=0.6)
    decision = SideTracker(egocentric=True, mirrored=True).decide([unsure], WIDTH, HEIGHT)
    assert [hand.side for hand in decision.hands] == [LEFT]


def test_a_followed_hand_keeps_its_side_through_an_unsure_flip() -> None:
    """Many sure 'right' frames, then one unsure 'left' at the same place: still right."""
    tracker = SideTracker(egocentric=False)
    for _ in range(5):
        tracker.decide([_hand(RIGHT, (300.0, 200.0), (0.0, -1.0), 0.95)], WIDTH, HEIGHT)
    flipped = tracker.decide([_hand(LEFT, (305.0, 200.0), (0.0, -1.0), 0.7)], WIDTH, HEIGHT)
    assert [hand.side for hand in flipped.hands] == [RIGHT]


def test_a_hand_whose_first_label_was_wrong_turns_with_the_evidence() -> None:
    """One 'left' frame, then 'right' frames at the same place (a few frames apart): right."""
    tracker = SideTracker(egocentric=False)
    first = tracker.decide([_hand(LEFT, (300.0, 200.0), (0.0, -1.0), 0.82)], WIDTH, HEIGHT)
    assert [hand.side for hand in first.hands] == [LEFT]
    for _ in range(4):
        tracker.decide([], WIDTH, HEIGHT)
    later = tracker.decide([_hand(RIGHT, (290.0, 200.0), (0.0, -1.0), 0.89)], WIDTH, HEIGHT)
    assert [hand.side for hand in later.hands] == [RIGHT]


def test_a_reset_forgets_the_followed_hands() -> None:
    """After a reset (a new scene) a hand at a followed hand's place starts afresh."""
    tracker = SideTracker(egocentric=False)
    for _ in range(5):
        tracker.decide([_hand(RIGHT, (300.0, 200.0), (0.0, -1.0), 0.99)], WIDTH, HEIGHT)
    tracker.reset()
    again = tracker.decide([_hand(LEFT, (300.0, 200.0), (0.0, -1.0), 0.7)], WIDTH, HEIGHT)
    assert [hand.side for hand in again.hands] == [LEFT]


def test_two_hands_labelled_alike_become_one_per_side_or_one_hand() -> None:
    """Far apart: the less likely right one is left; on top of each other: a duplicate."""
    apart = SideTracker(False).decide([_hand(RIGHT, (100.0, 200.0), (0.0, -1.0), 0.8),
                                       _hand(RIGHT, (400.0, 200.0), (0.0, -1.0), 0.95)],
                                      WIDTH, HEIGHT)
    assert sorted(hand.side for hand in apart.hands) == [LEFT, RIGHT]
    assert next(h for h in apart.hands if h.side == RIGHT).confidence == 0.95
    assert apart.duplicates == 0 and apart.relabelled == 1
    same = SideTracker(False).decide([_hand(RIGHT, (100.0, 200.0), (0.0, -1.0), 0.8),
                                      _hand(RIGHT, (102.0, 200.0), (0.0, -1.0), 0.95)],
                                     WIDTH, HEIGHT)
    assert [(hand.side, hand.confidence) for hand in same.hands] == [(RIGHT, 0.95)]
    assert same.duplicates == 1 and same.indices == (1,)


def test_two_hands_on_a_head_mounted_view_take_their_arms_sides() -> None:
    """Both labelled 'left' unsurely; the one whose arm comes from the right is right."""
    hands = [_hand(LEFT, (150.0, 420.0), (0.2, -1.0), 0.6),
             _hand(LEFT, (600.0, 150.0), (-1.0, -0.2), 0.55)]
    decision = SideTracker(egocentric=True).decide(hands, WIDTH, HEIGHT)
    by_place = {int(hand.joints_2d[WRIST, 0]): hand.side for hand in decision.hands}
    assert by_place == {150: LEFT, 600: RIGHT}
