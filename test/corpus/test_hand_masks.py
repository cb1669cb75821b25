"""Masks and boxes rendered from hand annotations (``data/hand_masks.py``)."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.corpus.hand_masks import capsule_masks
from infinihand_ros.corpus.hand_masks import masks_to_boxes
from infinihand_ros.corpus.hand_masks import mesh_masks
from infinihand_ros.mano.capsules import joint_radii
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest


@pytest.fixture(scope='module')
def synthetic_frames() -> tuple[SyntheticSequence, list]:
    """Return a tiny generated sequence (both hands) and its frames."""
    sequence = SyntheticSequence(SynthConfig(width=160, height=120, noise_sigma=0.0), 5, 6)
    return sequence, list(sequence)


def test_capsule_masks_match_the_generators(synthetic_frames: tuple) -> None:
    """Rendered from the ground truth, masks contain the generator's and differ only by scene.

    The generator's masks lose the pixels where the table or a box covers a hand; every other
    pixel agrees, and the radii equal the generator's.
    """
    sequence, frames = synthetic_frames
    for track in sequence.tracks:
        np.testing.assert_allclose(joint_radii(track.betas), track.radii)
    compared = 0
    for frame in frames:
        joints = np.stack([hand.joints_cam for hand in frame.hands])
        radii = np.stack([joint_radii(hand.mano_cam.betas) for hand in frame.hands])
        masks = capsule_masks(joints, radii, np.ones(2, bool), frame.intrinsics.matrix(),
                              160, 120)
        for hand in frame.hands:
            ours = masks[hand.side]
            assert not np.any(hand.mask & ~ours)  # nothing outside our surface
            extra = ours & ~hand.mask
            scene_depth = frame.depth[extra]
            # Pixels we add are those where the scene is in front of the hand in the render.
            assert np.all(scene_depth < hand.joints_cam[:, 2].max() + radii.max())
            compared += int(hand.mask.sum())
    assert compared > 500


def test_boxes_are_tight_and_exclusive() -> None:
    """A mask's box spans its first to one past its last row and column."""
    masks = np.zeros((2, 10, 12), bool)
    masks[1, 2:5, 3:9] = True
    np.testing.assert_array_equal(masks_to_boxes(masks), [[0, 0, 0, 0], [3, 2, 9, 5]])


def test_nearer_hand_wins_and_absent_hand_is_empty() -> None:
    """Two overlapping hands: the nearer one owns the shared pixels; an absent side is empty."""
    k = np.array([[100.0, 0, 40], [0, 100.0, 30], [0, 0, 1]])
    base = np.zeros((21, 3))
    base[:, 0] = np.linspace(-0.05, 0.05, 21)
    joints = np.stack([base + [0, 0, 0.4], base + [0, 0, 0.3]])
    radii = np.full((2, 21), 0.01)
    masks = capsule_masks(joints, radii, np.array([True, True]), k, 80, 60)
    assert masks[1].sum() > 0 and not np.any(masks[0] & masks[1])
    assert masks[1, 30, 40] and not masks[0, 30, 40]
    only_left = capsule_masks(joints, radii, np.array([True, False]), k, 80, 60)
    assert only_left[1].sum() == 0 and only_left[0, 30, 40]


def test_mesh_masks_fill_a_square() -> None:
    """Two triangles of a 10 cm square at 0.5 m cover its 20 x 20 pixel image."""
    k = np.array([[100.0, 0, 40], [0, 100.0, 30], [0, 0, 1]])
    square = np.array([[-0.05, -0.05, 0.5], [0.05, -0.05, 0.5], [0.05, 0.05, 0.5],
                       [-0.05, 0.05, 0.5]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    masks = mesh_masks(np.stack([square, square]), faces, np.array([False, True]), k, 80, 60)
    assert masks[0].sum() == 0
    np.testing.assert_array_equal(masks_to_boxes(masks)[1], [30, 20, 51, 41])


def test_bad_intrinsics_are_refused() -> None:
    """A K with a zero focal length raises InputError."""
    with pytest.raises(InputError, match='positive focal lengths'):
        capsule_masks(np.zeros((2, 21, 3)), np.ones((2, 21)), np.ones(2, bool),
                      np.zeros((3, 3)), 10, 10)
