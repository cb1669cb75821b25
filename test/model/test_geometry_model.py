"""Tests of model/geometry_model.py: LingBot-Map parity of the paper config, tiny forward."""

from dataclasses import replace
import json
from pathlib import Path

from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.geometry_stream import GeometryStream
import pytest
import torch

KEYS_FILE = Path('/work/shared/design/keys/lingbot_map_gctstream.json')
UPSTREAM_PREFIXES = ('aggregator', 'camera_head', 'depth_head')
LINGBOT_MAP_PARAMS = 1_157_943_540


@pytest.fixture(scope='module')
def paper_model() -> GeometryModel:
    """Return the paper-size model on the meta device (no memory allocated)."""
    with torch.device('meta'):
        return GeometryModel(load_geometry_config(named_config_path('paper')))


def test_paper_config_has_lingbot_map_parameter_count(paper_model: GeometryModel) -> None:
    """The aggregator, camera head and depth head hold exactly LingBot-Map's parameters."""
    count = sum(parameter.numel() for name, parameter in paper_model.named_parameters()
                if name.split('.')[0] in UPSTREAM_PREFIXES)
    assert count == LINGBOT_MAP_PARAMS
    assert sum(p.numel() for p in paper_model.mask_head.parameters()) == sum(
        p.numel() for p in paper_model.depth_head.parameters())


@pytest.mark.skipif(not KEYS_FILE.exists(), reason='design key reference not available')
def test_paper_config_state_dict_matches_lingbot_map_keys(paper_model: GeometryModel) -> None:
    """Every upstream key exists with its shape, and no other key under those prefixes."""
    reference = json.loads(KEYS_FILE.read_text())['keys']
    ours = {name: list(tensor.shape) for name, tensor in paper_model.state_dict().items()
            if name.split('.')[0] in UPSTREAM_PREFIXES}
    assert len(reference) == 1342
    assert ours == reference


def test_tiny_config_streams_one_frame(rng) -> None:
    """The tiny model returns every per-frame output with the documented shapes and ranges."""
    config = load_geometry_config(named_config_path('tiny'))
    torch.manual_seed(0)
    model = GeometryModel(config).eval()
    height, width = config.aggregator.image_height, config.aggregator.image_width
    images = torch.from_numpy(rng.random((1, 1, 3, height, width), dtype='float32'))
    with torch.no_grad():
        output = GeometryStream(model).step(images)
    grid = config.aggregator.patch_grid
    assert output.pose_encoding.shape == (1, 1, 9)
    assert len(output.pose_encoding_iterations) == config.camera_head.num_iterations
    assert output.depth.shape == output.depth_conf.shape == (1, 1, height, width)
    assert output.hand_masks.shape == (1, 1, 2, height, width)
    assert output.patch_features.shape == (1, 1, 2 * config.aggregator.embed_dim, *grid)
    assert output.patch_size == config.aggregator.patch_size
    assert bool((output.depth > 0).all()) and bool((output.depth_conf >= 1).all())
    assert 0.0 <= float(output.hand_masks.min()) and float(output.hand_masks.max()) <= 1.0
    assert bool((output.pose_encoding[..., 7:] >= 0).all())


def test_mask_head_starts_from_depth_head(micro_model: GeometryModel) -> None:
    """All mask-head weights equal the depth head's except the fresh final layer."""
    depth = micro_model.depth_head.state_dict()
    for name, tensor in micro_model.mask_head.state_dict().items():
        if name.startswith('scratch.output_conv2.2.'):
            assert not torch.equal(tensor, depth[name])
        else:
            assert torch.equal(tensor, depth[name]), name


def test_patch_features_are_last_selected_layer(micro_model: GeometryModel, rng) -> None:
    """patch_features is the last selected layer's patch tokens laid out on the patch grid."""
    images = torch.from_numpy(rng.random((1, 2, 3, 56, 70), dtype='float32'))
    stream = GeometryStream(micro_model)
    schedule_plan = stream.schedule.plan([True, True])
    memories = micro_model.new_memories()
    with torch.no_grad():
        aggregated = micro_model.aggregator(images, schedule_plan, memories[0])
        output = stream.step(images)
    tokens = aggregated.layers[-1][0, 1, aggregated.patch_start:]
    # token of patch row 2, column 3 (row-major, 5 columns)
    torch.testing.assert_close(output.patch_features[0, 1, :, 2, 3], tokens[2 * 5 + 3])


def test_depth_on_demand_equals_the_depth_head_run_with_the_block(micro_model: GeometryModel,
                                                                  rng) -> None:
    """A block run without the depth head gives each frame's depth later, the same values."""
    images = torch.from_numpy(rng.random((1, 3, 3, 56, 70), dtype='float32'))
    with torch.no_grad():
        full = GeometryStream(micro_model).step(images)
        lazy = GeometryStream(micro_model).step(images, depth=False)
        assert lazy.depth is None and lazy.depth_conf is None and full.dense_input is None
        torch.testing.assert_close(lazy.pose_encoding, full.pose_encoding)
        for frame in range(3):  # 2 anchors then 1 frame: two blocks' tokens joined
            torch.testing.assert_close(micro_model.frame_depth(lazy.dense_input, frame),
                                       full.depth[0, frame])


@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs a CUDA device')
def test_cuda_bf16_stream_matches_shapes_and_is_finite(micro_model: GeometryModel) -> None:
    """On CUDA the aggregator runs in bf16 autocast and the heads give finite float32 outputs."""
    stream = GeometryStream(micro_model.cuda())
    with torch.no_grad():
        stream.step(torch.rand(1, 2, 3, 56, 70, device='cuda'))
        output = stream.step(torch.rand(1, 3, 3, 56, 70, device='cuda'))
    assert output.depth.dtype == torch.float32 and output.depth.shape == (1, 3, 56, 70)
    assert bool(torch.isfinite(output.pose_encoding).all())
    assert bool(torch.isfinite(output.hand_masks).all())


def test_vggt_style_spatial_rope_streams(make_micro_config, rng) -> None:
    """With 2D RoPE in the global blocks (VGGT weights) the stream runs and stays causal."""
    config = make_micro_config(anchor_frames=1, window=2)
    config = replace(config, aggregator=replace(config.aggregator, global_rope='spatial2d'))
    torch.manual_seed(0)
    stream = GeometryStream(GeometryModel(config).eval())
    frames = torch.from_numpy(rng.random((1, 3, 3, 56, 70), dtype='float32'))
    with torch.no_grad():
        together = stream.step(frames).pose_encoding
        stream.reset()
        apart = torch.cat([stream.step(frames[:, i:i + 1]).pose_encoding for i in range(3)], 1)
    torch.testing.assert_close(together, apart, rtol=1e-4, atol=1e-4)
