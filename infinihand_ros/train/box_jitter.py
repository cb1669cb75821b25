"""Random scale and shift of the ground-truth hand boxes a training step runs on (ours).

The hand branch reads depth from how large the hand looks in its crop, and the crop follows the
box. Trained only on tight ground-truth boxes, it learns "box size = hand size" and turns box
errors of the predicted masks into depth errors (measured: held-out depth error correlated
-0.8 with the log box-size error). Jittering the ground-truth boxes, as the crop-based hand
estimators do, makes the prediction follow the hand rather than the box. The paper does not
say; ``train.box_jitter`` in the config sets it (zero: off).
"""

from dataclasses import dataclass

from infinihand_ros.core.errors import ConfigError
import torch


@dataclass(frozen=True)
class BoxJitter:
    """How much ground-truth boxes are perturbed (section ``train.box_jitter``).

    Attributes:
        scale: width and height are multiplied by one factor drawn from [1 - scale, 1 + scale].
        shift: the centre moves by up to this fraction of the width (x) and height (y).

    """

    scale: float = 0.0
    shift: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.scale < 1.0 or not 0.0 <= self.shift <= 1.0:
            raise ConfigError(f'train.box_jitter: need 0 <= scale < 1 and 0 <= shift <= 1, got '
                              f'scale {self.scale!r}, shift {self.shift!r}')

    @property
    def enabled(self) -> bool:
        """Return whether any jitter is applied."""
        return self.scale > 0.0 or self.shift > 0.0


def jitter_boxes(boxes: torch.Tensor, jitter: BoxJitter, generator: torch.Generator
                 ) -> torch.Tensor:
    """Return (..., 4) ``[x0, y0, x1, y1]`` boxes scaled and shifted about their centres.

    The draws come from ``generator`` (a training run's box generator, saved with its
    checkpoints), one scale and one (x, y) shift per box.
    """
    centre = (boxes[..., :2] + boxes[..., 2:]) / 2.0
    size = boxes[..., 2:] - boxes[..., :2]
    shape = boxes.shape[:-1]
    factor = 1.0 + jitter.scale * (2.0 * torch.rand(shape, generator=generator) - 1.0)
    offset = jitter.shift * (2.0 * torch.rand((*shape, 2), generator=generator) - 1.0)
    centre = centre + offset.to(boxes.dtype) * size
    half = size * factor[..., None].to(boxes.dtype) / 2.0
    return torch.cat((centre - half, centre + half), dim=-1)
