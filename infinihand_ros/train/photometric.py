"""Random brightness, contrast and saturation of a training clip's images (ours).

The bundled model's hand masks turned out brittle to exposure: on held-out frames where the mask
head found neither hand, scaling the image by 1.4 made it find both, while the same scaling of
every frame lowered recall overall (0.80 -> 0.73). The synthetic scenes draw their lighting per
sequence, so a model sees few exposures of each scene. Colour jitter, as image models are usually
trained with, widens that. One factor of each kind per clip (every frame of a clip changes alike,
as one camera's exposure would), applied in the order brightness, contrast, saturation, each
result clipped to [0, 1] (torchvision's ``ColorJitter`` formulas, grey = ITU-R 601 luma). The
labels do not change. The paper does not say; ``train.photometric`` in the config sets it
(zero: off).
"""

from dataclasses import dataclass

from infinihand_ros.core.errors import ConfigError
import torch

#: ITU-R BT.601 luma weights of R, G, B.
LUMA_WEIGHTS = (0.299, 0.587, 0.114)


@dataclass(frozen=True)
class PhotometricJitter:
    """How much a clip's colours are perturbed (section ``train.photometric``).

    Attributes:
        brightness: the image is multiplied by a factor drawn from [1 - b, 1 + b].
        contrast: each frame's distance from its mean grey is scaled by a factor from
            [1 - c, 1 + c].
        saturation: each pixel's distance from its own grey is scaled by a factor from
            [1 - s, 1 + s].

    """

    brightness: float = 0.0
    contrast: float = 0.0
    saturation: float = 0.0

    def __post_init__(self) -> None:
        amounts = {'brightness': self.brightness, 'contrast': self.contrast,
                   'saturation': self.saturation}
        bad = {name: value for name, value in amounts.items() if not 0.0 <= value < 1.0}
        if bad:
            raise ConfigError(f'train.photometric: each amount must be in [0, 1), got {bad}')

    @property
    def enabled(self) -> bool:
        """Return whether any jitter is applied."""
        return self.brightness > 0.0 or self.contrast > 0.0 or self.saturation > 0.0


def luma(images: torch.Tensor) -> torch.Tensor:
    """Return the (..., 1, H, W) grey of (..., 3, H, W) RGB images."""
    weights = torch.tensor(LUMA_WEIGHTS, dtype=images.dtype, device=images.device)
    return (images * weights[:, None, None]).sum(dim=-3, keepdim=True)


def jitter_photometric(images: torch.Tensor, jitter: PhotometricJitter,
                       generator: torch.Generator) -> torch.Tensor:
    """Return (B, S, 3, H, W) uint8 clips with one random colour change per clip.

    The draws come from ``generator`` (a training run's step generator, saved with its
    checkpoints): B brightness, then B contrast, then B saturation factors, uniform in
    ``1 +- amount``.
    """
    batch = images.shape[0]
    shape = (batch,) + (1,) * (images.dim() - 1)

    def factors(amount: float) -> torch.Tensor:
        draws = 2.0 * torch.rand(batch, generator=generator) - 1.0
        return (1.0 + amount * draws).reshape(shape).to(images.device)

    brightness = factors(jitter.brightness)
    contrast = factors(jitter.contrast)
    saturation = factors(jitter.saturation)
    pixels = images.float() / 255.0
    pixels = (pixels * brightness).clamp(0.0, 1.0)
    mean = luma(pixels).mean(dim=(-3, -2, -1), keepdim=True)
    pixels = ((pixels - mean) * contrast + mean).clamp(0.0, 1.0)
    grey = luma(pixels)
    pixels = ((pixels - grey) * saturation + grey).clamp(0.0, 1.0)
    return (pixels * 255.0).round().to(torch.uint8)
