"""One shape per side over time (engine/output/shape.py)."""

from dataclasses import replace

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.engine.output.shape import reshape_hand
from infinihand_ros.engine.output.shape import ShapeConsensus
from infinihand_ros.engine.world_placement import place_in_world
from infinihand_ros.mano.builtin import BuiltinHandModel
import numpy as np
from result_builders import make_hand
from scipy.spatial.transform import Rotation
import torch


def test_confident_betas_are_averaged_by_confidence_then_fixed() -> None:
    """Weighted mean of confident samples after min_samples; later samples change nothing."""
    consensus = ShapeConsensus(ShapeConfig(min_confidence=0.5, min_samples=2))
    consensus.observe(make_hand(RIGHT, confidence=0.6, betas=np.full(10, 1.0)))
    assert consensus.shared(RIGHT) is None
    consensus.observe(make_hand(RIGHT, confidence=0.2, betas=np.full(10, 9.0)))  # ignored
    consensus.observe(make_hand(RIGHT, confidence=1.0, betas=np.full(10, 3.0)))
    expected = (0.6 * 1.0 + 1.0 * 3.0) / 1.6
    np.testing.assert_allclose(consensus.shared(RIGHT), np.full(10, expected))
    consensus.observe(make_hand(RIGHT, confidence=1.0, betas=np.full(10, -5.0)))
    np.testing.assert_allclose(consensus.shared(RIGHT), np.full(10, expected))
    assert consensus.shared(LEFT) is None


def _model_hand(model: BuiltinHandModel, betas: np.ndarray, pose: CameraPose):
    """Return a hand whose joints are the model's for ``betas``, placed in the world by pose."""
    rng = np.random.default_rng(4)
    mano = ManoParams(rng.normal(scale=0.3, size=3), rng.normal(scale=0.2, size=(15, 3)), betas,
                      np.array([0.05, -0.02, 0.4]))
    with torch.inference_mode():
        joints = model(torch.as_tensor(mano.global_orient[None]),
                       torch.as_tensor(mano.hand_pose[None]), torch.as_tensor(betas[None]),
                       torch.as_tensor(mano.transl[None])).joints[0].double().numpy()
    hand = make_hand(RIGHT, betas=betas)
    return replace(hand, mano_cam=mano, joints_cam=joints, mano_world=None,
                   joints_world=pose.to_world(joints)), joints


def test_reshape_keeps_the_wrist_and_takes_the_shared_shape() -> None:
    """Root-relative camera joints become the model's for the shared betas; wrist unchanged."""
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    pose = CameraPose.identity()
    hand, joints = _model_hand(model, np.zeros(10), pose)
    shared = np.linspace(-1.0, 1.0, 10)
    _, joints_shared = _model_hand(model, shared, pose)
    reshaped = reshape_hand(hand, shared, model)
    np.testing.assert_allclose(reshaped.joints_cam[0], joints[0], atol=1e-12)
    np.testing.assert_allclose(reshaped.joints_cam - reshaped.joints_cam[0],
                               joints_shared - joints_shared[0], atol=1e-9)
    np.testing.assert_array_equal(reshaped.mano_cam.betas, shared)
    assert np.abs(joints_shared - joints_shared[0] - (joints - joints[0])).max() > 1e-4
    same = reshape_hand(hand, np.zeros(10), model)
    np.testing.assert_allclose(same.joints_cam, hand.joints_cam, atol=1e-12)


def test_reshape_in_the_world_frame_matches_the_model_there() -> None:
    """With world-frame params too, the world joints become the model's for the shared betas."""
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    pose = CameraPose(Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix(),
                      np.array([1.0, 2.0, 0.5]))
    hand, _ = _model_hand(model, np.zeros(10), pose)
    hand = place_in_world((hand,), pose)[0]
    shared = np.linspace(-1.0, 1.0, 10)
    reshaped = reshape_hand(hand, shared, model)
    with torch.inference_mode():
        world = model(*(torch.as_tensor(value[None]) for value in (
            reshaped.mano_world.global_orient, reshaped.mano_world.hand_pose, shared,
            reshaped.mano_world.transl))).joints[0].double().numpy()
    np.testing.assert_allclose(reshaped.joints_world[0], hand.joints_world[0], atol=1e-12)
    np.testing.assert_allclose(reshaped.joints_world - reshaped.joints_world[0],
                               world - world[0], atol=1e-9)
    np.testing.assert_allclose(reshaped.joints_world, pose.to_world(reshaped.joints_cam),
                               atol=1e-9)
    np.testing.assert_array_equal(reshaped.mano_world.betas, shared)
