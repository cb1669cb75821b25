"""Keyframe parts put back together by stamp (ros/bundle_adjustment/keyframe_assembly.py)."""

from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import KeyframeAssembler
import pytest

PARTS = ('image', 'depth', 'pose')


def test_a_set_completes_in_any_order_and_interleaved() -> None:
    """Parts of two stamps arriving mixed give each set once it is whole."""
    assembler = KeyframeAssembler(PARTS, 4)
    assert assembler.add('pose', 2, 'p2') is None
    assert assembler.add('image', 1, 'i1') is None
    assert assembler.add('depth', 1, 'd1') is None
    assert assembler.add('image', 2, 'i2') is None
    assert assembler.add('pose', 1, 'p1') == {'image': 'i1', 'depth': 'd1', 'pose': 'p1'}
    assert len(assembler) == 1
    assert assembler.add('depth', 2, 'd2') == {'pose': 'p2', 'image': 'i2', 'depth': 'd2'}
    assert len(assembler) == 0 and assembler.dropped == 0


def test_incomplete_stamps_beyond_the_limit_are_dropped_oldest_first() -> None:
    """With room for two, a third incomplete stamp drops the oldest (counted)."""
    assembler = KeyframeAssembler(PARTS, 2)
    for stamp in (1, 2, 3):
        assembler.add('image', stamp, stamp)
    assert assembler.dropped == 1 and len(assembler) == 2
    assembler.add('depth', 1, 'late')
    assert assembler.dropped == 2  # stamp 1 came back incomplete and pushed out stamp 2
    assert assembler.add('depth', 3, 'd') is None
    assert assembler.add('pose', 3, 'p') == {'image': 3, 'depth': 'd', 'pose': 'p'}


def test_unknown_part_and_bad_limits_are_refused() -> None:
    """A part name not in the set and max_pending 0 raise ValueError naming them."""
    with pytest.raises(ValueError, match='mask'):
        KeyframeAssembler(PARTS, 2).add('mask', 1, None)
    with pytest.raises(ValueError, match='max_pending'):
        KeyframeAssembler(PARTS, 0)
