"""The hand-depth correction of the metric scale: measured per frame, stored with a checkpoint."""

import json

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.eval.scale_calibration import frame_correction
from infinihand_ros.model.io.bundled import hand_depth_correction
from infinihand_ros.model.io.bundled import SCALE_CALIBRATION_FILE
import numpy as np
import pytest


def _frame(hand_factor: float) -> tuple:
    """Return a scene 2 m away, its engine depth half the truth, with one hand 0.5 m away.

    The engine puts the hand ``hand_factor`` times too far relative to the scene.
    """
    true_depth = np.full((60, 80), 2.0)
    hand_mask = np.zeros((60, 80), dtype=bool)
    hand_mask[20:40, 30:50] = True
    true_depth[hand_mask] = 0.5
    depth = true_depth / 2.0
    depth[hand_mask] *= hand_factor
    rng = np.random.default_rng(0)
    joints_2d = np.stack([rng.uniform(30, 49, 21), rng.uniform(20, 39, 21)], axis=-1)[None]
    return true_depth, depth, hand_mask, joints_2d, np.full((1, 21), 0.5)


@pytest.mark.parametrize('hand_factor', [1.0, 1.4, 0.8])
def test_a_frame_gives_how_much_too_far_the_hands_are(hand_factor: float) -> None:
    assert frame_correction(*_frame(hand_factor)) == pytest.approx(hand_factor)


def test_a_frame_without_hands_or_scene_gives_nan() -> None:
    true_depth, depth, mask, joints, depths = _frame(1.0)
    assert np.isnan(frame_correction(true_depth, depth, mask, joints[:0], depths[:0]))
    assert np.isnan(frame_correction(np.zeros_like(true_depth), depth, mask, joints, depths))


def test_a_checkpoint_without_a_calibration_is_not_corrected(tmp_path) -> None:
    assert hand_depth_correction(tmp_path) == 1.0
    (tmp_path / SCALE_CALIBRATION_FILE).write_text(json.dumps({'hand_depth_correction': 1.25}))
    assert hand_depth_correction(tmp_path) == 1.25


@pytest.mark.parametrize('text', ['{', '{"other": 1}', '{"hand_depth_correction": -1}',
                                  '{"hand_depth_correction": "NaN"}'])
def test_a_bad_calibration_file_is_named(tmp_path, text: str) -> None:
    (tmp_path / SCALE_CALIBRATION_FILE).write_text(text)
    with pytest.raises(CheckpointError, match=SCALE_CALIBRATION_FILE):
        hand_depth_correction(tmp_path)
