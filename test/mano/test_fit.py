"""MANO fitting to 3D keypoints recovers known hands (``mano/fit.py``)."""

from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import InputError
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.fit import fit_mano
from infinihand_ros.mano.fit import ManoFitConfig
from infinihand_ros.mano.fit import model_joints
from infinihand_ros.synth.known_tracks import known_track
import numpy as np
import pytest
import torch

FRAMES = 20
TOLERANCE_MM = 2.0


@pytest.mark.parametrize('side', [0, 1])
def test_fit_recovers_known_joints_within_2mm(side: int) -> None:
    """Exact keypoints of known parameters are refitted to within 2 mm at every joint."""
    track = known_track(np.random.default_rng(7 + side), side, FRAMES)
    result = fit_mano(BuiltinHandModel(side, dtype=torch.float64), track.joints)
    assert np.nanmax(result.joint_errors_mm) < TOLERANCE_MM
    assert result.frame_errors_mm.shape == (FRAMES,)
    assert np.all(result.frame_errors_mm < TOLERANCE_MM)
    error_mm = 1000.0 * np.linalg.norm(result.joints - track.joints, axis=-1)
    np.testing.assert_allclose(error_mm, result.joint_errors_mm)
    np.testing.assert_allclose(result.betas, np.broadcast_to(result.betas[0], result.betas.shape))


def test_fit_bridges_invalid_joints_and_frames() -> None:
    """Joints and a whole frame marked invalid are not fitted but follow from the rest."""
    track = known_track(np.random.default_rng(3), 1, FRAMES)
    keypoints = track.joints.copy()
    valid = np.ones(keypoints.shape[:2], bool)
    valid[5, :] = False
    valid[:, 8] = False  # no index tip anywhere
    keypoints[~valid] = 1e3  # garbage where invalid must not matter
    result = fit_mano(BuiltinHandModel(1, dtype=torch.float64), keypoints, valid)
    assert np.isnan(result.frame_errors_mm[5])
    assert np.all(np.isnan(result.joint_errors_mm[:, 8]))
    observed = np.arange(21) != 8
    bridged_mm = 1000.0 * np.linalg.norm(result.joints[5] - track.joints[5], axis=-1)[observed]
    # Minimal acceleration bridges a gap about as well as interpolating the neighbours does.
    midpoint = 0.5 * (track.joints[4] + track.joints[6])
    interpolation_mm = 1000.0 * np.linalg.norm(midpoint - track.joints[5], axis=-1)[observed]
    assert bridged_mm.max() < interpolation_mm.max()
    assert np.nanmax(result.joint_errors_mm) < 2.0 * TOLERANCE_MM


def test_smoothness_damps_keypoint_noise() -> None:
    """With 3 mm keypoint noise the smoothed fit is nearer the truth than the keypoints are."""
    rng = np.random.default_rng(11)
    track = known_track(rng, 0, FRAMES)
    noisy = track.joints + rng.normal(scale=0.003, size=track.joints.shape)
    result = fit_mano(BuiltinHandModel(0, dtype=torch.float64), noisy,
                      config=ManoFitConfig(smoothness_weight=1.0))
    fit_error = np.linalg.norm(result.joints - track.joints, axis=-1).mean()
    noise_error = np.linalg.norm(noisy - track.joints, axis=-1).mean()
    assert fit_error < 0.8 * noise_error


def test_fit_rejects_wrong_shapes() -> None:
    """Keypoints and validity of the wrong shape raise InputError naming the input."""
    model = BuiltinHandModel(1, dtype=torch.float64)
    with pytest.raises(InputError, match='keypoints: expected shape'):
        fit_mano(model, np.zeros((4, 20, 3)))
    with pytest.raises(InputError, match='valid: expected shape'):
        fit_mano(model, np.zeros((4, 21, 3)), np.ones((4, 20), bool))


def test_a_warm_start_at_the_answer_stays_there() -> None:
    """initial=: started at the true parameters, one L-BFGS step keeps the joints (< 0.1 mm)."""
    model = BuiltinHandModel(1, dtype=torch.float64)
    rng = np.random.default_rng(4)
    truth = ManoParams(rng.normal(0, 0.5, 3), rng.normal(0, 0.2, (15, 3)), rng.normal(0, 0.5, 10),
                       np.array([0.1, -0.05, 0.4]))
    with torch.no_grad():
        joints = model(*(torch.as_tensor(v)[None] for v in (
            truth.global_orient, truth.hand_pose, truth.betas, truth.transl))).joints[0].numpy()
    cold = fit_mano(model, joints[None], config=ManoFitConfig(iterations=1))
    warm = fit_mano(model, joints[None], config=ManoFitConfig(iterations=1), initial=truth)
    assert np.nanmax(warm.joint_errors_mm) < 0.1 < np.nanmax(cold.joint_errors_mm)
    np.testing.assert_allclose(warm.betas[0], truth.betas, atol=1e-3)


@pytest.mark.parametrize('side', [0, 1])
def test_numpy_posed_skeleton_equals_the_model(side: int) -> None:
    """model_joints' numpy posing of the float64 built-in skeleton is the model's forward pass.

    The MediaPipe hand source lifts with float64 copies of the hand models (the numpy path).
    """
    model = BuiltinHandModel(side).to(torch.float64)
    rng = np.random.default_rng(side)
    for _ in range(5):
        params = ManoParams(rng.normal(0, 1.0, 3), rng.normal(0, 0.5, (15, 3)),
                            rng.normal(0, 1.0, 10), rng.normal(0, 0.3, 3))
        with torch.no_grad():
            expected = model(*(torch.as_tensor(value[None]) for value in (
                params.global_orient, params.hand_pose, params.betas, params.transl))).joints[0]
        np.testing.assert_allclose(model_joints(model, params), expected.numpy(), atol=1e-12)
