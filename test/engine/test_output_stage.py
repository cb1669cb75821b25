"""The engine's output stage (engine/output/stage.py): identity, shared shape, smoothing."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.output.config import OutputConfig
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.engine.output.stage import OutputStage
from infinihand_ros.mano.builtin import BuiltinHandModel
import numpy as np
from result_builders import make_hand
from result_builders import make_result
from result_builders import PALM_JOINTS

MS = 1_000_000
MODELS = (BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT))


def test_a_flipped_label_is_undone_and_stamps_pass() -> None:
    """A hand that stays put keeps its side when the model flips the label for a frame."""
    stage = OutputStage(OutputConfig(shape=ShapeConfig(enabled=False)), MODELS)
    first = stage.apply(make_result(0, (make_hand(LEFT, (100, 200)),)))
    flipped = stage.apply(make_result(33 * MS, (make_hand(RIGHT, (102, 200)),), index=1))
    assert [hand.side for hand in first.hands] == [LEFT]
    assert [hand.side for hand in flipped.hands] == [LEFT]
    assert flipped.timestamp_ns == 33 * MS and flipped.frame_index == 1
    stage.reset()  # a new stream: the model's label wins again
    again = stage.apply(make_result(66 * MS, (make_hand(RIGHT, (102, 200)),), index=2))
    assert [hand.side for hand in again.hands] == [RIGHT]


def test_a_source_that_decides_sides_is_not_relabelled() -> None:
    """relabel=False (MediaPipe's sides are decided over time already): a side change stands."""
    stage = OutputStage(OutputConfig(shape=ShapeConfig(enabled=False)), MODELS, relabel=False)
    stage.apply(make_result(0, (make_hand(LEFT, (100, 200)),)))
    turned = stage.apply(make_result(33 * MS, (make_hand(RIGHT, (102, 200)),), index=1))
    assert [hand.side for hand in turned.hands] == [RIGHT]


def test_a_new_scene_keeps_the_label_at_the_same_pixels() -> None:
    """After a cut, a hand where the old scene's was is a new hand: its own label stands."""
    stage = OutputStage(OutputConfig(shape=ShapeConfig(enabled=False)), MODELS)
    stage.apply(make_result(0, (make_hand(LEFT, (100, 200)),)))
    stage.new_scene()
    cut = stage.apply(make_result(33 * MS, (make_hand(RIGHT, (102, 200)),), index=1))
    assert [hand.side for hand in cut.hands] == [RIGHT]


def test_the_shared_shape_replaces_per_frame_betas_after_enough_samples() -> None:
    """After min_samples confident hands every hand of that side gets their mean betas."""
    stage = OutputStage(OutputConfig(shape=ShapeConfig(min_confidence=0.5, min_samples=2)),
                        MODELS)
    betas = [np.full(10, 0.1), np.full(10, 0.3), np.full(10, 2.0)]
    out = [stage.apply(make_result(i * 33 * MS, (make_hand(RIGHT, betas=b),), index=i))
           for i, b in enumerate(betas)]
    np.testing.assert_allclose(out[0].hands[0].mano_cam.betas, betas[0])  # too few samples
    np.testing.assert_allclose(out[2].hands[0].mano_cam.betas, np.full(10, 0.2))


def test_smoothing_applies_to_world_joints() -> None:
    """With one_euro the second sample of a moved hand lands between the two positions."""
    config = OutputConfig(shape=ShapeConfig(enabled=False),
                          smoothing=SmoothingConfig(mode='one_euro', min_cutoff_hz=0.1))
    stage = OutputStage(config, MODELS)
    stage.apply(make_result(0, (make_hand(RIGHT),)))
    moved = make_hand(RIGHT, joints_world=PALM_JOINTS + 1.0)
    out = stage.apply(make_result(100 * MS, (moved,), index=1)).hands[0].joints_world
    assert np.all((out > PALM_JOINTS) & (out < PALM_JOINTS + 1.0))
