"""HandBranch forward on a synthetic frame (tiny config): shapes, consistency, exact mirroring."""

import json
from pathlib import Path

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.mano.mirror import mirror_points
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.frames import hand_to_camera
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.hand.hand_branch import HandBranch
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np
import pytest
import torch

#: Width of the fake backbone features (the tiny geometry branch's 2 x 192) and their patch.
FEATURE_DIM = 384
PATCH = 14
WILOR_KEYS = Path('/work/shared/design/keys/wilor_backbone.json')


@pytest.fixture(scope='module')
def branch() -> HandBranch:
    """Return a seeded tiny hand branch in float64 (exact comparisons), eval mode."""
    torch.manual_seed(0)
    return HandBranch(load_hand_branch_config('tiny'), FEATURE_DIM).double().eval()


def _inputs(frame: SynthFrame, rng: np.random.Generator) -> tuple:
    """Image, random patch features, K and the frame's boxes (left, right) as tensors."""
    image = torch.as_tensor(frame.rgb, dtype=torch.float64).permute(2, 0, 1)[None] / 255.0
    height, width = image.shape[-2:]
    features = torch.as_tensor(rng.normal(size=(1, FEATURE_DIM, height // PATCH, width // PATCH)))
    k = torch.as_tensor(frame.intrinsics.matrix())[None]
    boxes = HandBoxes(torch.as_tensor(np.stack([hand.box_xyxy for hand in frame.hands])),
                      torch.zeros(2, dtype=torch.long),
                      torch.tensor([hand.side for hand in frame.hands]))
    return image, features, k, boxes


def test_forward_shapes_and_finite(branch: HandBranch, synth_frame: SynthFrame,
                                   rng: np.random.Generator) -> None:
    with torch.no_grad():
        out = branch(*_inputs(synth_frame, rng))
    expected = {'joints_cam': (2, 21, 3), 'joints_2d': (2, 21, 2), 'landmarks_crop': (2, 21, 2),
                'log_depth': (2,), 'confidence': (2,), 'root_joint': (2, 3)}
    for name, shape in expected.items():
        value = getattr(out, name)
        assert value.shape == shape, name
        assert torch.isfinite(value).all(), name
    for mano in (out.mano_crop, out.mano_cam):
        assert mano.global_orient.shape == (2, 3) and mano.hand_pose.shape == (2, 15, 3)
        assert mano.betas.shape == (2, 10) and mano.transl.shape == (2, 3)
    assert ((out.confidence >= 0) & (out.confidence <= 1)).all()
    assert (out.joints_cam[..., 2] > 0).all()  # hands in front of the camera at init


def test_outputs_are_consistent(branch: HandBranch, synth_frame: SynthFrame,
                                rng: np.random.Generator) -> None:
    image, features, k, boxes = _inputs(synth_frame, rng)
    with torch.no_grad():
        out = branch(image, features, k, boxes)
        for i, side in enumerate((LEFT, RIGHT)):
            mano = out.mano_cam
            joints = branch.hand_models[side](mano.global_orient[i:i + 1],
                                              mano.hand_pose[i:i + 1], mano.betas[i:i + 1],
                                              mano.transl[i:i + 1]).joints
            np.testing.assert_allclose(out.joints_cam[i:i + 1].numpy(), joints.numpy(),
                                       atol=1e-9)
    orient_c, transl_c = hand_to_camera(out.mano_crop.global_orient, out.mano_crop.transl,
                                        out.cameras.rotation_h_from_c, out.root_joint)
    np.testing.assert_allclose(transl_c.numpy(), out.mano_cam.transl.numpy(), atol=1e-12)
    projected = out.joints_cam @ k[0].T
    np.testing.assert_allclose(out.joints_2d.numpy(),
                               (projected[..., :2] / projected[..., 2:]).numpy(), atol=1e-9)
    # The wrist's depth in the crop frame is exp(l_z).
    wrist_h = out.mano_crop.transl + out.root_joint
    np.testing.assert_allclose(wrist_h[:, 2].numpy(), out.log_depth.exp().numpy(), rtol=1e-12)


def test_mirrored_input_gives_mirrored_output(branch: HandBranch, synth_frame: SynthFrame,
                                              rng: np.random.Generator) -> None:
    image, features, k, boxes = _inputs(synth_frame, rng)
    width = image.shape[-1]
    k_mirror = k.clone()
    k_mirror[:, 0, 2] = width - 1 - k[:, 0, 2]
    xyxy = boxes.boxes_xyxy.clone()
    xyxy[:, 0], xyxy[:, 2] = width - boxes.boxes_xyxy[:, 2], width - boxes.boxes_xyxy[:, 0]
    mirrored_boxes = HandBoxes(xyxy, boxes.batch_index, 1 - boxes.sides)
    with torch.no_grad():
        out = branch(image, features, k, boxes)
        mir = branch(image.flip(-1), features.flip(-1), k_mirror, mirrored_boxes)
    tol = {'atol': 1e-9}
    np.testing.assert_allclose(mir.landmarks_crop.numpy(), out.landmarks_crop.numpy(), **tol)
    np.testing.assert_allclose(mir.confidence.numpy(), out.confidence.numpy(), **tol)
    np.testing.assert_allclose(mir.mano_cam.betas.numpy(), out.mano_cam.betas.numpy(), **tol)
    np.testing.assert_allclose(mir.mano_cam.global_orient.numpy(),
                               mirror_axis_angle(out.mano_cam.global_orient).numpy(), **tol)
    np.testing.assert_allclose(mir.mano_cam.hand_pose.numpy(),
                               mirror_axis_angle(out.mano_cam.hand_pose).numpy(), **tol)
    np.testing.assert_allclose(mir.mano_cam.transl.numpy(),
                               mirror_points(out.mano_cam.transl).numpy(), **tol)
    np.testing.assert_allclose(mir.joints_cam.numpy(), mirror_points(out.joints_cam).numpy(),
                               **tol)
    expected_2d = out.joints_2d.clone()
    expected_2d[..., 0] = width - 1 - out.joints_2d[..., 0]
    np.testing.assert_allclose(mir.joints_2d.numpy(), expected_2d.numpy(), atol=1e-7)


def test_gradients_reach_every_trainable_part(synth_frame: SynthFrame,
                                              rng: np.random.Generator) -> None:
    torch.manual_seed(1)
    branch = HandBranch(load_hand_branch_config('tiny'), FEATURE_DIM)
    image, features, k, boxes = _inputs(synth_frame, rng)
    features = features.float().requires_grad_(True)
    out = branch(image.float(), features, k.float(), boxes)
    (out.joints_cam.sum() + out.landmarks_crop.sum() + out.confidence.sum()).backward()
    for name in ('backbone.patch_embed.proj.weight', 'backbone.decpose.weight',
                 'adapter.fc1.weight', 'fusion.weight', 'mano_head.output.weight',
                 'landmark_head.output.weight'):
        grad = branch.get_parameter(name).grad
        assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0, name
    assert features.grad.abs().sum() > 0


def test_no_boxes_gives_empty_outputs(branch: HandBranch, synth_frame: SynthFrame,
                                      rng: np.random.Generator) -> None:
    image, features, k, _ = _inputs(synth_frame, rng)
    empty = HandBoxes(torch.zeros(0, 4, dtype=torch.float64), torch.zeros(0, dtype=torch.long),
                      torch.zeros(0, dtype=torch.long))
    with torch.no_grad():
        out = branch(image, features, k, empty)
    assert out.joints_cam.shape == (0, 21, 3) and out.mano_cam.hand_pose.shape == (0, 15, 3)


def test_bad_inputs_are_named(branch: HandBranch, synth_frame: SynthFrame,
                              rng: np.random.Generator) -> None:
    image, features, k, boxes = _inputs(synth_frame, rng)
    with pytest.raises(InputError, match='does not tile'):
        branch(image, features[..., :-1], k, boxes)
    with pytest.raises(InputError, match='features: expected'):
        branch(image, features[:, :10], k, boxes)
    with pytest.raises(InputError, match='batch_index'):
        branch(image, features, k, HandBoxes(boxes.boxes_xyxy, boxes.batch_index + 1,
                                             boxes.sides))
    with pytest.raises(InputError, match='sides'):
        HandBoxes(boxes.boxes_xyxy, boxes.batch_index, torch.tensor([0, 2]))


@pytest.mark.skipif(not WILOR_KEYS.is_file(), reason='WiLoR key reference not available')
def test_paper_branch_backbone_keys_are_wilor_keys() -> None:
    reference = json.loads(WILOR_KEYS.read_text())['keys']
    expected = {key: tuple(shape) for key, shape in reference.items()
                if key.startswith('backbone.')}
    with torch.device('meta'):
        branch = HandBranch(load_hand_branch_config('paper'), feature_dim=2048)
    got = {key: tuple(value.shape) for key, value in branch.state_dict().items()
           if key.startswith('backbone.')}
    assert got == expected
