"""Tests of model/heads/mask_head.py: boxes from thresholded masks, expanded x1.5."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.model.heads.mask_head import masks_to_boxes
import pytest
import torch


def test_box_is_tight_box_expanded_about_its_centre() -> None:
    """A 4x6 blob at rows 2..5, cols 10..15 gives its box scaled by 1.5 about the centre."""
    masks = torch.zeros(1, 1, 2, 20, 30)
    masks[0, 0, 1, 2:6, 10:16] = 0.9
    boxes, valid = masks_to_boxes(masks, threshold=0.5, min_pixels=4, expand=1.5)
    assert valid.tolist() == [[[False, True]]]
    # tight [10, 2, 16, 6], centre (13, 4), half size (4.5, 3)
    torch.testing.assert_close(boxes[0, 0, 1], torch.tensor([8.5, 1.0, 17.5, 7.0]))
    assert boxes[0, 0, 0].abs().sum() == 0


def test_small_or_faint_masks_give_no_box() -> None:
    """Below the pixel count or the threshold there is no valid box."""
    masks = torch.zeros(2, 10, 10)
    masks[0, 1, 1] = 1.0
    masks[1] = 0.4
    _, valid = masks_to_boxes(masks, threshold=0.5, min_pixels=2, expand=1.5)
    assert valid.tolist() == [False, False]


def test_bad_arguments_are_rejected() -> None:
    """A 1-D input or a non-positive factor raises InputError."""
    with pytest.raises(InputError, match='H, W'):
        masks_to_boxes(torch.zeros(5), 0.5, 1, 1.5)
    with pytest.raises(InputError, match='positive'):
        masks_to_boxes(torch.zeros(5, 5), 0.5, 1, 0.0)
