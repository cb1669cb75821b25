"""Tests of the level-by-level forward kinematics against a plain per-joint loop."""

from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.mano.kinematics import CHAIN_LEVELS
from infinihand_ros.mano.kinematics import forward_kinematics
from infinihand_ros.mano.kinematics import offsets_from_positions
from infinihand_ros.mano.kinematics import PARENTS_WITH_TIPS
from infinihand_ros.mano.kinematics import TIP_PARENTS
import numpy as np
import roma
import torch


def _reference_kinematics(local: torch.Tensor, offsets: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Compose transforms joint by joint in MANO order (the textbook loop)."""
    rotations = [local[:, 0]]
    positions = [offsets[:, 0]]
    for joint in range(1, offsets.shape[1]):
        parent = PARENTS_WITH_TIPS[joint]
        positions.append(positions[parent] + (rotations[parent] @ offsets[:, joint, :, None])[
            ..., 0])
        if joint < NUM_MANO_JOINTS:
            rotations.append(rotations[parent] @ local[:, joint])
    return torch.stack(rotations, 1), torch.stack(positions, 1)


def test_levels_and_tips_follow_the_mano_tree() -> None:
    assert CHAIN_LEVELS == ((1, 4, 7, 10, 13), (2, 5, 8, 11, 14), (3, 6, 9, 12, 15))
    for upper, lower in zip(CHAIN_LEVELS, CHAIN_LEVELS[1:]):
        assert tuple(MANO_PARENTS[joint] for joint in lower) == upper
    # Tips in order thumb, index, middle, ring, pinky hang off thumb3, index3, middle3, ...
    assert TIP_PARENTS == (15, 3, 6, 12, 9)


def test_matches_the_per_joint_loop(rng: np.random.Generator) -> None:
    local = roma.rotvec_to_rotmat(torch.as_tensor(rng.normal(size=(4, NUM_MANO_JOINTS, 3))))
    for count in (NUM_MANO_JOINTS, NUM_JOINTS):
        offsets = torch.as_tensor(rng.normal(size=(4, count, 3)))
        rotations, positions = forward_kinematics(local, offsets)
        want_rotations, want_positions = _reference_kinematics(local, offsets)
        assert positions.shape == (4, count, 3)
        torch.testing.assert_close(rotations, want_rotations)
        torch.testing.assert_close(positions, want_positions)


def test_identity_rotations_give_back_the_rest_positions(rng: np.random.Generator) -> None:
    rest = torch.as_tensor(rng.normal(size=(2, NUM_JOINTS, 3)))
    identity = torch.eye(3, dtype=rest.dtype).expand(2, NUM_MANO_JOINTS, 3, 3)
    rotations, positions = forward_kinematics(identity, offsets_from_positions(rest))
    torch.testing.assert_close(positions, rest)
    torch.testing.assert_close(rotations, identity)
