"""Tests of the joint orders, maps and side helpers."""

from infinihand_ros.core import hand_conventions as hc
import pytest


def test_mano_to_openpose_is_a_permutation_with_named_targets() -> None:
    assert sorted(hc.MANO_TO_OPENPOSE) == list(range(hc.NUM_JOINTS))
    mano_with_tips = hc.MANO_JOINT_NAMES + hc.MANO_TIP_NAMES
    # OpenPose joint k is MANO(+tips) joint MANO_TO_OPENPOSE[k]: the finger names must agree.
    for openpose_index, mano_index in enumerate(hc.MANO_TO_OPENPOSE):
        finger = hc.JOINT_NAMES[openpose_index].split('_')[0]
        assert mano_with_tips[mano_index].startswith(finger)


def test_openpose_to_mano_inverts_the_map() -> None:
    for k in range(hc.NUM_JOINTS):
        assert hc.MANO_TO_OPENPOSE[hc.OPENPOSE_TO_MANO[k]] == k


def test_parents_follow_the_mano_tree() -> None:
    # A joint's OpenPose parent is the OpenPose index of its MANO parent (tips hang off joint 3).
    tip_parents = {16: 15, 17: 3, 18: 6, 19: 12, 20: 9}
    for openpose_index, mano_index in enumerate(hc.MANO_TO_OPENPOSE):
        parent_mano = tip_parents.get(mano_index, hc.MANO_PARENTS[mano_index]
                                      if mano_index < hc.NUM_MANO_JOINTS else None)
        expected = -1 if parent_mano == -1 else hc.MANO_TO_OPENPOSE.index(parent_mano)
        assert hc.JOINT_PARENTS[openpose_index] == expected


def test_finger_joints_cover_all_but_the_wrist() -> None:
    flat = [j for finger in hc.FINGER_JOINTS for j in finger]
    assert flat == list(range(1, hc.NUM_JOINTS))


def test_side_names_round_trip_and_reject_bad_values() -> None:
    assert hc.side_from_name(' Left ') == hc.LEFT
    assert hc.side_name(hc.RIGHT) == 'right'
    with pytest.raises(ValueError, match='got 2'):
        hc.side_name(2)
    with pytest.raises(ValueError, match="got 'up'"):
        hc.side_from_name('up')
