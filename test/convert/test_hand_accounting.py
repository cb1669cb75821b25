"""Every hand the source found is written or dropped for a counted reason (hand_accounting.py)."""

from infinihand_ros.convert.hand_accounting import account_hands
from infinihand_ros.convert.hand_accounting import HandAccounting
from infinihand_ros.convert.lerobot_features import DEGENERATE_PALM
from infinihand_ros.convert.lerobot_features import NOT_DETECTED
from infinihand_ros.convert.lerobot_features import NOT_IN_WORLD
from infinihand_ros.convert.report import EpisodeReport


def test_found_hands_are_written_or_dropped_by_reason() -> None:
    """The source's drops over the episode, then the results' invalid hands; no hand is no drop."""
    before = {'found': 5, 'dropped_confidence': 1, 'dropped_duplicate': 0}
    after = {'found': 15, 'dropped_confidence': 2, 'dropped_duplicate': 2, 'hands': 12}
    invalid = [{'left': NOT_DETECTED}, {'right': NOT_IN_WORLD},
               {'left': DEGENERATE_PALM, 'right': NOT_IN_WORLD}, {}]
    accounting = account_hands(before, after, 4, invalid)
    assert accounting.found == 10 and accounting.written == 4
    assert accounting.dropped == {'under hands.min_confidence': 1, 'a hand seen twice': 2,
                                  NOT_IN_WORLD: 2, DEGENERATE_PALM: 1}
    assert accounting.adds_up
    assert not HandAccounting(found=3, written=1, dropped={'a hand seen twice': 1}).adds_up


def test_the_episode_report_prints_and_saves_the_accounting() -> None:
    """The report's lines and its JSON data carry the counts."""
    report = EpisodeReport('in.mcap', hands_found=HandAccounting(3, 2, {NOT_IN_WORLD: 1}))
    assert f'  hands found 3: written 2, 1 {NOT_IN_WORLD} (frames used)' in report.lines()
    assert report.to_dict()['hands_found'] == {'found': 3, 'written': 2,
                                               'dropped': {NOT_IN_WORLD: 1}}
