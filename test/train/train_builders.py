"""Builders of the training tests: micro model configs, test sequences, micro run settings."""

from pathlib import Path

from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import CameraHeadConfig
from infinihand_ros.model.config import DptConfig
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import MemoryConfig

#: Source frames of the test sequences (letterboxed to the micro model's 70 x 56).
SOURCE_SIZE = (96, 72)
#: Seeds and lengths of the test sequences.
SEQUENCES = ((3, 10), (5, 8))

MICRO_HAND_BRANCH = {
    'crop_size': 64, 'box_expansion': 1.5, 'default_crop_extent_m': 0.25, 'min_cam_scale': 0.1,
    'adapter_dim': 32, 'fusion_dim': 32, 'readout_channels': 4, 'head_hidden_dim': 64,
    'appearance': {'image_height': 64, 'image_width': 48, 'patch_size': 16, 'patch_padding': 2,
                   'embed_dim': 32, 'depth': 1, 'num_heads': 2, 'mlp_ratio': 2.0,
                   'qkv_bias': True, 'norm_eps': 1.0e-6},
}


def micro_geometry() -> GeometryConfig:
    """Return a geometry config small enough for per-test CPU training (4 x 5 patches)."""
    aggregator = AggregatorConfig(image_height=56, image_width=70, embed_dim=64, depth=2,
                                  num_heads=2, rope3d_split=(12, 10, 10),
                                  selected_layers=(0, 1, 1, 1))
    return GeometryConfig(aggregator=aggregator,
                          camera_head=CameraHeadConfig(trunk_depth=1, num_heads=2,
                                                       num_iterations=2),
                          dpt=DptConfig(features=16, out_channels=(16, 16, 32, 32),
                                        head_features=8),
                          memory=MemoryConfig(anchor_frames=2, window=2))


def run_settings(model_files: tuple[Path, Path], sequences: list[Path], **train: object
                 ) -> dict:
    """Return the ``train`` section of a micro run (Stage II, 2 + 2 x 2), ``train`` overrides."""
    geometry, hand = model_files
    settings = {
        'stage': 'stage2',
        'model': {'geometry': str(geometry), 'hand_branch': str(hand), 'seed': 0},
        'clip': {'anchor_frames': 2, 'window_frames': 2, 'num_windows': 2, 'frame_stride': 1,
                 'clip_step': 2},
        'data': {'sequences': [str(path) for path in sequences], 'num_workers': 0},
        'optim': {'groups': [{'name': 'camera', 'prefixes': ['geometry.camera_head'],
                              'lr': 1.0e-3},
                             {'name': 'rest', 'prefixes': [''], 'lr': 1.0e-3}],
                  'frozen': ['geometry.depth_head', 'hand_branch.hand_models'],
                  'warmup_steps': 1},
        'loss_groups': ['mask', 'landmarks', 'mano', 'world_joints', 'camera', 'temporal'],
        'batch_size': 1, 'steps': 4, 'seed': 0, 'gt_box_ratio': 0.5,
        'checkpoint_every': 2, 'device': 'cpu', 'cpu_threads': 1,
    }
    for key, value in train.items():
        if isinstance(value, dict):
            settings[key] = {**settings.get(key, {}), **value}
        else:
            settings[key] = value
    return settings
