"""Tests of train/photometric.py: the per-clip colour jitter of a training step."""

from collections.abc import Callable
from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.photometric import jitter_photometric
from infinihand_ros.train.photometric import luma
from infinihand_ros.train.photometric import PhotometricJitter
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.trainer import train
import pytest
import torch


def _clips(batch: int = 2, frames: int = 3, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return torch.randint(40, 216, (batch, frames, 3, 6, 8), generator=generator,
                         dtype=torch.uint8)


def test_brightness_multiplies_by_the_drawn_factor() -> None:
    """Brightness alone: a grey of 100 becomes round(100 * (1 + b (2u - 1))), u the first draw."""
    images = torch.full((1, 2, 3, 4, 4), 100, dtype=torch.uint8)
    out = jitter_photometric(images, PhotometricJitter(brightness=0.5),
                             torch.Generator().manual_seed(7))
    draw = torch.rand(1, generator=torch.Generator().manual_seed(7)).item()
    factor = 1.0 + 0.5 * (2.0 * draw - 1.0)
    assert torch.all(out == round(100 * factor))
    assert out.dtype == torch.uint8 and out.shape == images.shape


def test_contrast_keeps_a_flat_frame_and_saturation_keeps_a_grey_one() -> None:
    """A frame of one grey has no contrast to scale; a grey pixel has no saturation."""
    flat = torch.full((2, 1, 3, 5, 5), 120, dtype=torch.uint8)
    out = jitter_photometric(flat, PhotometricJitter(contrast=0.9), torch.Generator())
    assert torch.equal(out, flat)
    grey = _clips(2, 2)[:, :, :1].expand(-1, -1, 3, -1, -1).contiguous()
    out = jitter_photometric(grey, PhotometricJitter(saturation=0.9), torch.Generator())
    assert torch.equal(out, grey)


def test_contrast_and_saturation_scale_distances_by_their_factor() -> None:
    """Contrast and saturation scale distances from a grey by one factor in [1 - a, 1 + a].

    Contrast: the distance from the frame's mean grey; saturation: from each pixel's own grey
    (away from clipping, up to 8-bit rounding).
    """
    images = _clips(1, 1)
    pixels = images.float() / 255.0
    for jitter, centre in ((PhotometricJitter(contrast=0.3),
                            lambda x: luma(x).mean(dim=(-3, -2, -1), keepdim=True)),
                           (PhotometricJitter(saturation=0.3), luma)):
        out = jitter_photometric(images, jitter, torch.Generator().manual_seed(1)).float() / 255
        spread, new_spread = pixels - centre(pixels), out - centre(pixels)
        large = spread.abs() > 0.1
        ratio = (new_spread[large] / spread[large])
        assert 0.7 <= ratio.median() <= 1.3 and ratio.median() != pytest.approx(1.0, abs=1e-3)
        assert (ratio - ratio.median()).abs().max() < 0.05  # one factor, up to 8-bit rounding


def test_one_change_per_clip_and_reproducible_from_the_generator() -> None:
    """Frames of a clip change alike; clips differ; the same seed gives the same images."""
    frame = _clips(1, 1)
    images = frame.expand(2, 3, -1, -1, -1).contiguous()
    jitter = PhotometricJitter(brightness=0.4, contrast=0.4, saturation=0.4)
    out = jitter_photometric(images, jitter, torch.Generator().manual_seed(5))
    assert torch.equal(out[:, 0], out[:, 1]) and torch.equal(out[:, 0], out[:, 2])
    assert not torch.equal(out[0], out[1])
    assert torch.equal(out, jitter_photometric(images, jitter, torch.Generator().manual_seed(5)))


def test_zero_amounts_are_off_and_bad_amounts_are_config_errors() -> None:
    """No amount: disabled; negative or >= 1: a ConfigError naming train.photometric."""
    assert not PhotometricJitter().enabled and PhotometricJitter(saturation=0.1).enabled
    for bad in ({'brightness': -0.1}, {'contrast': 1.0}, {'saturation': 2.0}):
        with pytest.raises(ConfigError, match='train.photometric'):
            PhotometricJitter(**bad)


def test_a_run_with_colour_jitter_trains_other_images_and_resumes_bit_for_bit(
        write_run_config: Callable[..., Path], tmp_path: Path) -> None:
    """Colour jitter reaches the step and resumes bit for bit.

    Losses differ from a run without it, its draws are saved with the checkpoints (3 + 3
    resumed steps == 6 in one go) and the config loads back.
    """
    plain = load_train_config(write_run_config(steps=2, checkpoint_every=100))
    jittered = load_train_config(write_run_config(
        steps=6, checkpoint_every=3,
        photometric={'brightness': 0.4, 'contrast': 0.4, 'saturation': 0.4}))
    assert jittered.photometric == PhotometricJitter(0.4, 0.4, 0.4)
    whole = train(jittered, tmp_path / 'whole', progress=False)
    assert train(plain, tmp_path / 'plain', progress=False).losses[:1] != whole.losses[:1]
    train(jittered, tmp_path / 'split', stop_after=3, progress=False)
    second = train(jittered, tmp_path / 'split', resume=tmp_path / 'split', progress=False)
    assert second.losses == whole.losses[3:]
