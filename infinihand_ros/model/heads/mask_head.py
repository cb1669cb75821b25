"""Hand localisation (paper Sec. 3.2): a DPT mask head and boxes from its masks.

The mask head is a second ``DPTHead`` whose decoder (projections, resizing, RefineNet fusion,
first output convs) starts as a copy of the depth head's weights, with a freshly initialised
2-channel final layer: channel 0 = left hand, channel 1 = right hand (``core`` side convention),
sigmoid outputs. Boxes are the tight boxes of the thresholded masks expanded about their centre;
optionally (ours, not the paper's) of the connected region around the mask's peak only, so that
stray pixels away from the hand do not stretch its box; fragments of that region a few pixels
apart (a mask broken across a finger gap or a thin occluder) can be joined into it.
"""

from infinihand_ros.core.errors import InputError
from infinihand_ros.model.heads.dpt_head import DPTHead
import numpy as np
from scipy import ndimage
import torch
from torch import nn

NUM_MASK_CHANNELS = 2
FINAL_LAYER_PREFIX = 'scratch.output_conv2.2.'


@torch.no_grad()
def init_mask_head_from_depth(mask_head: DPTHead, depth_head: DPTHead) -> None:
    """Copy every depth-head weight except the final layer into ``mask_head``; re-init that one.

    Raises:
        ValueError: when the two decoders differ in anything but their final layer.

    """
    depth_state = depth_head.state_dict()
    mask_state = mask_head.state_dict()
    if set(depth_state) != set(mask_state):
        raise ValueError('mask head and depth head have different decoders; build both from '
                         'the same DptConfig')
    for name, tensor in mask_state.items():
        if not name.startswith(FINAL_LAYER_PREFIX):
            tensor.copy_(depth_state[name])
    final = mask_head.scratch.output_conv2[2]
    if not isinstance(final, nn.Conv2d):
        raise ValueError('mask head: scratch.output_conv2[2] is not the final 1x1 conv')
    final.reset_parameters()


def activate_masks(raw: torch.Tensor) -> torch.Tensor:
    """Return hand probabilities (B, S, 2, H, W) in [0, 1]: sigmoid of the raw mask map."""
    return torch.sigmoid(raw)


def peak_regions(masks: torch.Tensor, inside: torch.Tensor, join_px: int = 0) -> torch.Tensor:
    """Return ``inside`` (..., H, W) with only the 8-connected region of each mask's peak kept.

    Args:
        masks: (..., H, W) probabilities.
        inside: (..., H, W) bool, the pixels above the threshold.
        join_px: regions are found on ``inside`` dilated by a square of half-width ``join_px``,
            so pixels up to ``2 * join_px + 1`` apart (Chebyshev distance) join one region; only
            ``inside`` pixels are kept. 0: plain 8-connectivity.

    """
    if join_px < 0:
        raise InputError(f'region join distance must be >= 0 pixels, got {join_px}')
    shape = inside.shape
    probabilities = masks.detach().reshape(-1, shape[-2] * shape[-1]).float().cpu().numpy()
    above = inside.detach().reshape(-1, *shape[-2:]).cpu().numpy()
    kept = np.zeros_like(above)
    connectivity = np.ones((3, 3), bool)
    for index, mask in enumerate(above):
        peak = np.unravel_index(int(np.argmax(probabilities[index])), mask.shape)
        if mask[peak]:
            joined = (ndimage.maximum_filter(mask, size=2 * join_px + 1, mode='constant')
                      if join_px else mask)
            labels, _ = ndimage.label(joined, structure=connectivity)
            kept[index] = (labels == labels[peak]) & mask
    return torch.from_numpy(kept).reshape(shape).to(inside.device)


def masks_to_boxes(masks: torch.Tensor, threshold: float, min_pixels: int, expand: float,
                   peak_region: bool = False, join_px: int = 0
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """Return expanded boxes and validity from hand masks.

    Args:
        masks: (..., H, W) probabilities in [0, 1] (e.g. (B, S, 2, H, W)).
        threshold: a pixel belongs to the hand when its probability exceeds this.
        min_pixels: fewer hand pixels than this -> no box (valid False).
        expand: the tight box's width and height are multiplied by this about its centre.
        peak_region: box (and count) only the 8-connected region around each mask's peak.
        join_px: with ``peak_region``, fragments up to ``2 * join_px + 1`` pixels apart join the
            peak's region (``peak_regions``).

    Returns:
        boxes: (..., 4) float32 ``[x0, y0, x1, y1]`` in pixels (pixel-edge coordinates, so a
            single pixel (u, v) spans [u, u + 1]); not clipped to the image, zeros when invalid.
        valid: (...,) bool.

    Raises:
        InputError: for fewer than two dimensions or a non-positive ``expand``.

    """
    if masks.dim() < 2:
        raise InputError(f'masks: expected (..., H, W), got shape {tuple(masks.shape)}')
    if expand <= 0:
        raise InputError(f'box expand factor must be positive, got {expand}')
    inside = masks > threshold
    if peak_region:
        inside = peak_regions(masks, inside, join_px)
    height, width = inside.shape[-2:]
    rows = inside.any(dim=-1)
    cols = inside.any(dim=-2)
    row_index = torch.arange(height, device=masks.device)
    col_index = torch.arange(width, device=masks.device)
    y0 = torch.where(rows, row_index, height).amin(dim=-1)
    y1 = torch.where(rows, row_index + 1, 0).amax(dim=-1)
    x0 = torch.where(cols, col_index, width).amin(dim=-1)
    x1 = torch.where(cols, col_index + 1, 0).amax(dim=-1)
    tight = torch.stack((x0, y0, x1, y1), dim=-1).float()
    centre = (tight[..., :2] + tight[..., 2:]) / 2.0
    half = (tight[..., 2:] - tight[..., :2]) * (expand / 2.0)
    boxes = torch.cat((centre - half, centre + half), dim=-1)
    valid = inside.flatten(-2).sum(dim=-1) >= min_pixels
    return torch.where(valid[..., None], boxes, torch.zeros_like(boxes)), valid
