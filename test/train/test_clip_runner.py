"""The per-clip pass: box choice, dense hands, landmark targets, schedule and groups."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.model.hand.crop_camera import build_crop_cameras
from infinihand_ros.train.clip_runner import choose_boxes
from infinihand_ros.train.loss_adapter import crop_landmark_targets
from infinihand_ros.train.loss_adapter import mask_logits
from infinihand_ros.train.loss_adapter import scatter_hands
from infinihand_ros.train.optim import assign_parameters
from infinihand_ros.train.optim import schedule_factor
from infinihand_ros.train.train_config import OptimConfig
from infinihand_ros.train.train_config import ParamGroupConfig
import pytest
import torch
from torch import nn


def test_boxes_are_ground_truth_when_drawn_or_undetected() -> None:
    gt = torch.tensor([[[0., 0., 4., 4.], [10., 10., 14., 14.]]]).repeat(2, 1, 1)
    pred = gt + 1.0
    gt_valid = torch.tensor([[True, True], [True, False]])
    pred_valid = torch.tensor([[True, False], [True, True]])
    use_gt = torch.tensor([[False, False], [True, False]])
    boxes = choose_boxes(gt, gt_valid, pred, pred_valid, use_gt)
    assert boxes.batch_index.tolist() == [0, 0, 1] and boxes.sides.tolist() == [0, 1, 0]
    # (0, left): predicted; (0, right): nothing detected -> ground truth; (1, left): drawn.
    torch.testing.assert_close(boxes.boxes_xyxy, torch.stack((pred[0, 0], gt[0, 1], gt[1, 0])))


def test_scatter_places_rows_and_keeps_gradients() -> None:
    values = torch.arange(6.0).reshape(3, 2).requires_grad_()
    dense = scatter_hands(values, torch.tensor([0, 2, 2]), torch.tensor([1, 0, 1]), 3)
    assert dense.shape == (3, 2, 2)
    torch.testing.assert_close(dense[2, 1], values[2].detach())
    assert float(dense[1].detach().abs().sum()) == 0.0
    dense.sum().backward()
    torch.testing.assert_close(values.grad, torch.ones(3, 2))


def test_landmark_targets_follow_the_crop_convention() -> None:
    """A centred box: the axis point maps to the crop centre; mirrored for left hands."""
    intrinsics = torch.tensor([[100.0, 0.0, 49.5], [0.0, 100.0, 39.5], [0.0, 0.0, 1.0]])
    boxes = torch.tensor([[40.0, 30.0, 60.0, 50.0]] * 2)
    cameras = build_crop_cameras(boxes, intrinsics.expand(2, 3, 3), torch.tensor([False, True]),
                                 64, 1.5)
    joints = torch.zeros(2, 21, 3)
    joints[..., 2] = 0.5
    joints[:, 1, 0] = 0.05  # right of the axis
    joints[:, 2, 2] = -0.1  # behind the camera
    targets = crop_landmark_targets(joints, cameras)
    torch.testing.assert_close(targets[:, 0], torch.zeros(2, 2), atol=1e-5, rtol=0)
    assert targets[0, 1, 0] > 0.1 and torch.isclose(targets[1, 1, 0], -targets[0, 1, 0])
    assert bool(torch.isnan(targets[:, 2]).all())


def test_mask_logits_invert_the_sigmoid_inside_the_clamp() -> None:
    raw = torch.tensor([-3.0, 0.0, 2.0, 40.0])
    logits = mask_logits(torch.sigmoid(raw), 1e-6)
    torch.testing.assert_close(logits[:3], raw[:3], atol=1e-4, rtol=0)
    assert float(logits[3]) == pytest.approx(13.8155, abs=0.05)  # logit(1 - 1e-6), float32


def test_schedule_warms_up_then_anneals() -> None:
    factors = [schedule_factor(step, 10, 2, 0.1) for step in range(10)]
    assert factors[:2] == [0.5, 1.0]
    assert factors[2] == pytest.approx(1.0) and factors[-1] == pytest.approx(0.1)
    assert all(a >= b for a, b in zip(factors[2:], factors[3:]))


def test_parameters_are_frozen_grouped_or_refused() -> None:
    model = nn.Sequential(nn.Linear(2, 2), nn.Linear(2, 2), nn.Linear(2, 2))
    config = OptimConfig(groups=(ParamGroupConfig('first', ('0.',), 1e-3),
                                 ParamGroupConfig('rest', ('',), 1e-4)), frozen=('2.',))
    groups = assign_parameters(model, config)
    assert [name for name, _ in groups['first']] == ['0.weight', '0.bias']
    assert [name for name, _ in groups['rest']] == ['1.weight', '1.bias']
    assert not model[2].weight.requires_grad
    with pytest.raises(ConfigError, match=r"in no group and not frozen, e.g. \['1.weight'"):
        assign_parameters(model, OptimConfig(groups=(ParamGroupConfig('a', ('0.',), 1e-3),),
                                             frozen=('2.',)))
    with pytest.raises(ConfigError, match=r"\['b'\] match no trainable parameter"):
        assign_parameters(model, OptimConfig(groups=(ParamGroupConfig('a', ('',), 1e-3),
                                                     ParamGroupConfig('b', ('9.',), 1e-3))))
