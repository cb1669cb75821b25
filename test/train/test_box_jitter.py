"""Tests of train/box_jitter.py: the ground-truth box perturbation of a training step."""

from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.box_jitter import BoxJitter
from infinihand_ros.train.box_jitter import jitter_boxes
from infinihand_ros.train.recipe import load_recipe
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_config import named_train_config_path
from infinihand_ros.train.train_config import TrainConfig
import pytest
import torch

RECIPE = Path(__file__).parents[2] / 'models' / 'tiny_synthetic' / 'recipe.yaml'


def _boxes(count: int) -> torch.Tensor:
    centre = torch.tensor([100.0, 60.0]).expand(count, 2)
    half = torch.tensor([20.0, 10.0]).expand(count, 2)
    return torch.cat((centre - half, centre + half), dim=-1)


def test_jitter_stays_within_its_bounds_and_keeps_the_aspect_ratio() -> None:
    """Sizes scale by one factor in [0.7, 1.3]; centres move by up to 0.1 of the size."""
    boxes = _boxes(4000)
    out = jitter_boxes(boxes, BoxJitter(scale=0.3, shift=0.1), torch.Generator().manual_seed(0))
    size = out[:, 2:] - out[:, :2]
    factor = size / torch.tensor([40.0, 20.0])
    torch.testing.assert_close(factor[:, 0], factor[:, 1])
    assert 0.7 <= factor.min() < 0.72 and 1.28 < factor.max() <= 1.3
    shift = ((out[:, :2] + out[:, 2:]) / 2 - torch.tensor([100.0, 60.0])) / torch.tensor(
        [40.0, 20.0])
    assert shift.abs().max() <= 0.1 + 1e-6 and shift.abs().max() > 0.099


def test_jitter_is_reproducible_from_the_generator_and_zero_jitter_is_identity() -> None:
    """The same seed gives the same boxes; no scale and no shift leave them as they are."""
    boxes = _boxes(8).reshape(2, 2, 2, 4)
    jitter = BoxJitter(scale=0.2, shift=0.05)
    first = jitter_boxes(boxes, jitter, torch.Generator().manual_seed(3))
    second = jitter_boxes(boxes, jitter, torch.Generator().manual_seed(3))
    assert first.shape == boxes.shape and torch.equal(first, second)
    assert not torch.equal(first, boxes)
    assert not BoxJitter().enabled
    torch.testing.assert_close(jitter_boxes(boxes, BoxJitter(), torch.Generator()), boxes)


@pytest.mark.parametrize('scale, shift', [(-0.1, 0.0), (1.0, 0.0), (0.2, 1.5)])
def test_out_of_range_jitter_is_a_config_error(scale: float, shift: float) -> None:
    """Negative, total or over-large jitter names train.box_jitter."""
    with pytest.raises(ConfigError, match='train.box_jitter'):
        BoxJitter(scale=scale, shift=shift)


def test_the_shipped_settings_jitter_their_boxes() -> None:
    """The motion and heads settings jitter boxes; the camera phase (no hand loss) does not."""
    recipe = load_recipe(RECIPE)

    def setting(name: str) -> TrainConfig:
        return load_train_config(recipe.setting(name).config, recipe.setting(name).overrides)

    motion = setting('motion')
    assert motion.box_jitter.enabled and motion.peak_region_boxes
    heads = load_train_config(named_train_config_path('tiny_heads'))
    assert heads.box_jitter.enabled and 'geometry.aggregator' in heads.optim.frozen
    assert not setting('camera').box_jitter.enabled
