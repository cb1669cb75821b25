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


def test_peak_region_boxes_only_the_blob_around_the_peak() -> None:
    """A stray blob far from the hand stretches the plain box but not the peak-region one."""
    masks = torch.zeros(1, 2, 20, 30)
    masks[0, 0, 2:6, 10:16] = 0.9
    masks[0, 0, 3, 12] = 0.95                   # the peak, inside the hand blob
    masks[0, 0, 15:19, 25:29] = 0.8             # a larger stray blob, lower probability
    masks[0, 0, 10:20, 0:3] = 0.7
    plain, _ = masks_to_boxes(masks, 0.5, 4, expand=1.0)
    peaked, valid = masks_to_boxes(masks, 0.5, 4, expand=1.0, peak_region=True)
    torch.testing.assert_close(plain[0, 0], torch.tensor([0.0, 2.0, 29.0, 20.0]))
    torch.testing.assert_close(peaked[0, 0], torch.tensor([10.0, 2.0, 16.0, 6.0]))
    assert valid.tolist() == [[True, False]]


def test_peak_region_joins_diagonal_neighbours_and_counts_only_its_pixels() -> None:
    """8-connected pixels belong to the peak's region; min_pixels counts that region only."""
    masks = torch.zeros(1, 10, 10)
    masks[0, 1, 1] = 0.9
    masks[0, 2, 2] = 0.8                        # diagonal neighbour: same region
    masks[0, 6:9, 6:9] = 0.7                    # 9 pixels, another region
    boxes, valid = masks_to_boxes(masks, 0.5, 2, expand=1.0, peak_region=True)
    torch.testing.assert_close(boxes[0], torch.tensor([1.0, 1.0, 3.0, 3.0]))
    assert valid.tolist() == [True]
    _, valid = masks_to_boxes(masks, 0.5, 3, expand=1.0, peak_region=True)
    assert valid.tolist() == [False]            # 2 pixels around the peak, though 11 in all


def test_region_join_px_joins_fragments_within_twice_it_plus_one() -> None:
    """Fragments up to 2 * join_px + 1 pixels apart join the peak's region; farther ones do not."""
    masks = torch.zeros(1, 20, 40)
    masks[0, 5:9, 5:9] = 0.9                    # the peak's fragment, columns 5..8
    masks[0, 5, 6] = 0.95
    masks[0, 5:9, 13:16] = 0.8                  # column 13: 5 pixels from column 8
    masks[0, 5:9, 30:33] = 0.8                  # 15 pixels beyond column 15
    alone, _ = masks_to_boxes(masks, 0.5, 4, expand=1.0, peak_region=True)
    torch.testing.assert_close(alone[0], torch.tensor([5.0, 5.0, 9.0, 9.0]))
    for join_px, right_edge in ((1, 9.0), (2, 16.0), (6, 16.0), (7, 33.0)):
        boxes, valid = masks_to_boxes(masks, 0.5, 4, expand=1.0, peak_region=True,
                                      join_px=join_px)
        torch.testing.assert_close(boxes[0], torch.tensor([5.0, 5.0, right_edge, 9.0]))
        assert valid.tolist() == [True]


def test_region_join_counts_only_pixels_above_the_threshold() -> None:
    """Joining widens the region's reach, not its pixels: min_pixels still counts mask pixels."""
    masks = torch.zeros(1, 10, 10)
    masks[0, 1, 1] = 0.9
    masks[0, 1, 4] = 0.8                        # 3 pixels away: joined with join_px=1
    _, valid = masks_to_boxes(masks, 0.5, 2, expand=1.0, peak_region=True, join_px=1)
    assert valid.tolist() == [True]
    _, valid = masks_to_boxes(masks, 0.5, 3, expand=1.0, peak_region=True, join_px=1)
    assert valid.tolist() == [False]
    with pytest.raises(InputError, match='join distance'):
        masks_to_boxes(masks, 0.5, 2, expand=1.0, peak_region=True, join_px=-1)
