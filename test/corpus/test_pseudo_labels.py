"""Pseudo-labels from a bag (``data/pseudo_labels.py``) and the agreement figures."""

from pathlib import Path

from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.corpus.label_agreement import label_agreement
from infinihand_ros.corpus.pseudo_labels import pseudo_label_bag
from infinihand_ros.corpus.pseudo_labels import PseudoLabelConfig
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest


class _TruthSource:
    """Detections made from the generator's truth: exact pixels and hand-centred metric joints."""

    def __init__(self, frames: list) -> None:
        self._frames = frames

    def detect(self, rgb: np.ndarray, frame_index: int) -> list[Detection2D]:
        frame = self._frames[frame_index]
        intr = frame.intrinsics
        K = np.array([[intr.fx, 0, intr.cx], [0, intr.fy, intr.cy], [0, 0, 1.0]])
        return [Detection2D(h.side, project_points(h.joints_cam, K), np.ones(NUM_JOINTS), 0.9,
                            h.joints_cam - h.joints_cam.mean(axis=0))
                for h in frame.hands if h.visible]


@pytest.fixture(scope='module')
def synthetic_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    """Return a four-frame generated bag and its frames (with truth)."""
    sequence = SyntheticSequence(SynthConfig(width=128, height=96, noise_sigma=0.0), 4, 4)
    frames = list(sequence)
    path = tmp_path_factory.mktemp('bag') / 'bag'
    with BagSink(path) as sink:
        for frame in frames:
            sink.add(frame)
    return path, frames


def test_pnp_places_exact_detections_on_the_true_hands(synthetic_bag: tuple) -> None:
    """With exact pixels and metric shape, the labelled joints are the true camera joints."""
    path, frames = synthetic_bag
    sequence = pseudo_label_bag(path, _TruthSource(frames), PseudoLabelConfig())
    assert sequence.T_world_cam is None and sequence.num_frames == len(frames)
    checked = 0
    for index, frame in enumerate(frames):
        for hand in frame.hands:
            assert sequence.hand_present[index, hand.side] == hand.visible
            if hand.visible:
                np.testing.assert_allclose(sequence.joints_cam[index, hand.side],
                                           hand.joints_cam, atol=1e-4)
                assert sequence.hand_confidence[index, hand.side] == pytest.approx(0.9)
                checked += 1
    assert checked > 0
    assert sequence.read_rgb(1).shape == frames[1].rgb.shape


def test_low_confidence_detections_give_no_label(synthetic_bag: tuple) -> None:
    """Detections under ``min_confidence`` leave every hand unlabelled."""
    path, frames = synthetic_bag
    sequence = pseudo_label_bag(path, _TruthSource(frames), PseudoLabelConfig(min_confidence=0.95))
    assert not sequence.hand_present.any()
    assert not sequence.hand_confidence.any()


def test_agreement_counts_matches_misses_and_swaps() -> None:
    """Exact detections score 0; a swapped side counts as a miss and a swap."""
    truth = np.zeros((2, 2, NUM_JOINTS, 2))
    truth[..., 0] = np.arange(NUM_JOINTS)
    boxes = np.tile([0.0, 0.0, 20.0, 10.0], (2, 2, 1))
    visible = np.array([[True, False], [True, False]])
    exact = Detection2D(0, truth[0, 0], np.ones(NUM_JOINTS), 0.9)
    swapped = Detection2D(1, truth[1, 0] + 1.0, np.ones(NUM_JOINTS), 0.9)
    result = label_agreement([[exact], [swapped]], truth, boxes, visible)
    assert result.summary() == {'hand_frames': 2, 'matched': 1, 'missed': 1, 'side_swapped': 1,
                                'median': 0.0, 'mean': 0.0, 'p90': 0.0}
