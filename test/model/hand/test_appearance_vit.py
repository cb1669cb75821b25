"""The appearance ViT: WiLoR key/shape parity (meta device) and a tiny forward pass."""

import json
from pathlib import Path

from infinihand_ros.core.errors import InputError
from infinihand_ros.model.hand.appearance_vit import AppearanceViT
from infinihand_ros.model.hand.config import load_hand_branch_config
import numpy as np
import pytest
import torch

#: Reference keys and shapes of WiLoR's state dict (see the file's README).
WILOR_KEYS = Path('/work/shared/design/keys/wilor_backbone.json')
PREFIX = 'backbone.'


@pytest.mark.skipif(not WILOR_KEYS.is_file(), reason='WiLoR key reference not available')
def test_paper_config_matches_wilor_backbone_keys_and_shapes() -> None:
    reference = json.loads(WILOR_KEYS.read_text())['keys']
    expected = [(key[len(PREFIX):], tuple(shape)) for key, shape in reference.items()
                if key.startswith(PREFIX)]
    config = load_hand_branch_config('paper')
    with torch.device('meta'):
        model = AppearanceViT(config.appearance, default_cam_scale=8.0)
    got = [(key, tuple(value.shape)) for key, value in model.state_dict().items()]
    assert got == expected  # same names, shapes and order


def test_tiny_forward_shapes_and_coarse_hand_at_the_means(rng: np.random.Generator) -> None:
    config = load_hand_branch_config('tiny').appearance
    torch.manual_seed(0)
    model = AppearanceViT(config, default_cam_scale=8.0).eval()
    images = torch.as_tensor(rng.uniform(size=(2, 3, config.image_height, config.image_width)),
                             dtype=torch.float32)
    with torch.no_grad():
        out = model(images)
    grid_h, grid_w = config.grid_size
    assert out.features.shape == (2, config.embed_dim, grid_h, grid_w)
    assert out.pose_6d.shape == (2, 16, 6) and out.betas.shape == (2, 10)
    assert torch.isfinite(out.features).all()
    # Near-zero decoder initialisation: the coarse hand starts close to the mean buffers.
    np.testing.assert_allclose(out.cam[:, 0].numpy(), 8.0, atol=0.1)
    np.testing.assert_allclose(out.pose_6d.numpy(),
                               model.init_hand_pose.view(1, 16, 6).expand(2, -1, -1).numpy(),
                               atol=0.1)


def test_image_tokens_follow_their_pixels() -> None:
    """Changing one patch changes the features; the ViT sees every patch of its input."""
    config = load_hand_branch_config('tiny').appearance
    torch.manual_seed(0)
    model = AppearanceViT(config, default_cam_scale=8.0).eval()
    images = torch.zeros(1, 3, config.image_height, config.image_width)
    changed = images.clone()
    changed[..., -config.patch_size:, -config.patch_size:] = 1.0
    with torch.no_grad():
        assert not torch.allclose(model(images).features, model(changed).features)


def test_wrong_input_size_is_rejected() -> None:
    config = load_hand_branch_config('tiny').appearance
    model = AppearanceViT(config, default_cam_scale=8.0)
    with pytest.raises(InputError, match='appearance ViT input'):
        model(torch.zeros(1, 3, 64, 64))
