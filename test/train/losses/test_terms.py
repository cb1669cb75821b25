"""Tests of train/losses/terms.py: group results and L_joint."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import joint_loss
from infinihand_ros.train.losses import LandmarkLosses
from infinihand_ros.train.losses import MaskLosses
import pytest
import torch


def test_joint_loss_sums_the_group_totals() -> None:
    """L_joint = sum of ``total``; the unweighted terms do not enter."""
    mask = MaskLosses(total=torch.tensor(1.5), bce=torch.tensor(9.0), dice=torch.tensor(9.0))
    landmarks = LandmarkLosses(total=torch.tensor(0.25), l1=torch.tensor(9.0))
    assert joint_loss([mask, landmarks]).item() == 1.75
    assert joint_loss([mask]).item() == 1.5


def test_named_terms_for_logging() -> None:
    """Every field by name, with a prefix."""
    landmarks = LandmarkLosses(total=torch.tensor(0.5), l1=torch.tensor(1.0))
    assert {key: value.item() for key, value in landmarks.named_terms('2d/').items()} == {
        '2d/total': 0.5, '2d/l1': 1.0}


def test_joint_loss_refuses_nothing_or_other_things() -> None:
    """No groups, or a bare tensor, raise InputError saying what to pass."""
    with pytest.raises(InputError, match='got no loss groups'):
        joint_loss([])
    with pytest.raises(InputError, match='expected LossTerms results.*got Tensor'):
        joint_loss([torch.tensor(1.0)])
