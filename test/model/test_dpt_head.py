"""Tests of model/heads/dpt_head.py: the residual unit's upstream semantics."""

from infinihand_ros.model.heads.dpt_head import ResidualConvUnit
import torch


def test_residual_unit_adds_back_the_activated_input() -> None:
    """With zero convs the unit returns relu(x): negative entries come out as 0, not x."""
    unit = ResidualConvUnit(2)
    for conv in (unit.conv1, unit.conv2):
        torch.nn.init.zeros_(conv.weight)
        torch.nn.init.zeros_(conv.bias)
    x = torch.tensor([[[[-1.0, 2.0], [0.5, -3.0]], [[4.0, -0.25], [-2.0, 1.0]]]])
    torch.testing.assert_close(unit(x), torch.relu(x))


def test_residual_unit_matches_its_formula_with_weights() -> None:
    """relu(x) + conv2(relu(conv1(relu(x)))) on random weights and signed input."""
    torch.manual_seed(0)
    unit = ResidualConvUnit(3)
    x = torch.randn(1, 3, 5, 4)
    activated = torch.relu(x)
    expected = activated + unit.conv2(torch.relu(unit.conv1(activated)))
    torch.testing.assert_close(unit(x), expected)
    assert not torch.allclose(unit(x), x + unit.conv2(torch.relu(unit.conv1(activated))))
