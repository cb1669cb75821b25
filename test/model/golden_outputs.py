"""The golden-output case: the seeded tiny model's camera-space pass on two fixed frames.

``compute_golden_outputs()`` is shared by the test (``test_golden_outputs.py``) and the script
that regenerates the committed file (``scripts/regenerate_golden_outputs.py``), so both always
compute the same thing. The frames are closed-form patterns (no random generator, no synthetic
renderer) and the hand boxes are fixed, so only the network's numerics can change the outputs.
"""

from pathlib import Path

from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.infinihand_model import build_infinihand_model
import numpy as np
import torch

GOLDEN_PATH = Path(__file__).resolve().parent / 'golden' / 'tiny_outputs.safetensors'
#: Dense maps are stored every this-many pixels (the file stays small).
MAP_STRIDE = 4
#: Leading patch-feature channels stored.
FEATURE_CHANNELS = 16


def golden_frames(height: int, width: int) -> torch.Tensor:
    """Return (1, 2, 3, H, W) RGB in [0, 1]: two smooth, different, closed-form patterns."""
    v, u = np.mgrid[0:height, 0:width] / np.array([height, width])[:, None, None]
    frames = []
    for phase in (0.0, 0.7):
        red = 0.5 + 0.5 * np.sin(6.0 * u + phase)
        green = 0.5 + 0.5 * np.cos(4.0 * v - 2.0 * phase)
        blue = 0.5 + 0.5 * np.sin(3.0 * (u + v) + 3.0 * phase)
        frames.append(np.stack((red, green, blue)))
    return torch.as_tensor(np.stack(frames), dtype=torch.float32)[None]


def compute_golden_outputs(cpu_bf16: bool = False) -> dict[str, torch.Tensor]:
    """Return the tensors the golden file holds (seed 0, tiny configs, one anchor block).

    ``cpu_bf16`` runs the aggregator in bf16 (the engine's fast CPU path); the file holds the
    float32 reference.
    """
    geometry = load_geometry_config(named_config_path('tiny'))
    model = build_infinihand_model(geometry, load_hand_branch_config('tiny'), seed=0).eval()
    height, width = geometry.aggregator.image_height, geometry.aggregator.image_width
    images = golden_frames(height, width)
    boxes = HandBoxes(torch.tensor([[40.0, 50.0, 100.0, 120.0], [120.0, 30.0, 190.0, 110.0],
                                    [60.0, 60.0, 110.0, 140.0]]),
                      torch.tensor([0, 0, 1]), torch.tensor([0, 1, 1]))
    with torch.inference_mode():
        geometry, poses, used = model.run_geometry(images, model.new_stream(), True,
                                                   cpu_bf16=cpu_bf16)
        out = model.run_hands(images, geometry, poses, used, boxes)
    grid = (slice(None), slice(None), slice(None, None, MAP_STRIDE),
            slice(None, None, MAP_STRIDE))
    hands = out.hands
    return {
        'pose_encoding': out.geometry.pose_encoding,
        'depth': out.geometry.depth[grid],
        'depth_conf': out.geometry.depth_conf[grid],
        'hand_masks': out.geometry.hand_masks[:, :, :, ::MAP_STRIDE, ::MAP_STRIDE],
        'patch_features': out.geometry.patch_features[:, :, :FEATURE_CHANNELS],
        'T_world_cam': out.T_world_cam.float(),
        'global_orient': hands.mano_cam.global_orient, 'hand_pose': hands.mano_cam.hand_pose,
        'betas': hands.mano_cam.betas, 'transl': hands.mano_cam.transl,
        'joints_cam': hands.joints_cam, 'joints_2d': hands.joints_2d,
        'landmarks_crop': hands.landmarks_crop}
