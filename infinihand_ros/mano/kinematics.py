"""Batched forward kinematics on MANO's kinematic tree, shared by the built-in and MANO models.

MANO's tree is a wrist with five three-joint chains (index, middle, pinky, ring, thumb), so forward
kinematics runs one level of depth at a time: three steps of batched (B, 5, 3, 3) products instead
of a loop over joints. Rotations follow MANO: at rest every joint frame is aligned with the
canonical frame, ``G_0 = R_0``, ``G_i = G_parent(i) R_i`` and
``p_i = p_parent(i) + G_parent(i) o_i`` where ``o_i`` is the rest offset of joint i from its
parent. Fingertips (MANO indices 16-20, order thumb, index, middle, ring, pinky) hang off the third
joint of their finger.
"""

from typing import Final

from infinihand_ros.core.hand_conventions import MANO_JOINT_NAMES
from infinihand_ros.core.hand_conventions import MANO_PARENTS
from infinihand_ros.core.hand_conventions import MANO_TIP_NAMES
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
import torch

#: Suffixes that turn a tip name ('index_tip') into its parent MANO joint name ('index3').
_TIP_SUFFIX: Final = '_tip'
_LAST_JOINT_SUFFIX: Final = '3'


def _chain_levels(parents: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """Group the non-root joints by depth so that entry k of each level continues chain k.

    Raises:
        ValueError: if the tree is not a root with single-child chains.

    """
    children: dict[int, list[int]] = {joint: [] for joint in range(len(parents))}
    for joint, parent in enumerate(parents):
        if parent >= 0:
            children[parent].append(joint)
    levels = [tuple(children[0])]
    while True:
        nxt = [children[joint] for joint in levels[-1]]
        if all(not c for c in nxt):
            break
        if any(len(c) != 1 for c in nxt):
            raise ValueError(f'kinematic tree {parents} is not made of single-child chains')
        levels.append(tuple(c[0] for c in nxt))
    return tuple(levels)


#: Non-root MANO joints grouped by depth; column k is chain k (index, middle, pinky, ring, thumb).
CHAIN_LEVELS: Final = _chain_levels(MANO_PARENTS)
#: Parent MANO joint of each fingertip, in tip order (thumb, index, middle, ring, pinky).
TIP_PARENTS: Final = tuple(
    MANO_JOINT_NAMES.index(name.removesuffix(_TIP_SUFFIX) + _LAST_JOINT_SUFFIX)
    for name in MANO_TIP_NAMES)
#: Parent of each of the 21 MANO joints with tips (-1 for the wrist).
PARENTS_WITH_TIPS: Final = MANO_PARENTS + TIP_PARENTS
#: Tip index (16-20) that continues each chain, in chain order.
CHAIN_TIPS: Final = tuple(NUM_MANO_JOINTS + TIP_PARENTS.index(last) for last in CHAIN_LEVELS[-1])
#: Joint order produced by concatenating root, levels and chain tips; argsort gives MANO order.
_LEVEL_ORDER: Final = (0,) + sum(CHAIN_LEVELS, ()) + CHAIN_TIPS
_TO_MANO_ORDER: Final = tuple(_LEVEL_ORDER.index(joint) for joint in range(NUM_JOINTS))


def forward_kinematics(local_rotations: torch.Tensor,
                       offsets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Compose local joint rotations along MANO's tree.

    Args:
        local_rotations: (B, 16, 3, 3) rotation of each MANO joint relative to its parent
            (entry 0 is the global orientation of the wrist).
        offsets: (B, 16, 3) or (B, 21, 3) rest offsets in metres: entry 0 is the wrist position,
            entry i > 0 is joint i minus its parent at rest (tips 16-20 if 21 entries).

    Returns:
        (global_rotations (B, 16, 3, 3), positions (B, J, 3)) in MANO order, J = offsets' count.

    """
    with_tips = offsets.shape[1] == NUM_JOINTS
    batch = local_rotations.shape[0]
    chains = len(CHAIN_LEVELS[0])
    g_prev = local_rotations[:, :1].expand(batch, chains, 3, 3)
    p_prev = offsets[:, :1].expand(batch, chains, 3)
    rotations = [local_rotations[:, :1]]
    positions = [offsets[:, :1]]
    for level in CHAIN_LEVELS:
        index = list(level)
        p_prev = p_prev + torch.einsum('bkij,bkj->bki', g_prev, offsets[:, index])
        g_prev = g_prev @ local_rotations[:, index]
        rotations.append(g_prev)
        positions.append(p_prev)
    if with_tips:
        positions.append(p_prev + torch.einsum('bkij,bkj->bki', g_prev,
                                               offsets[:, list(CHAIN_TIPS)]))
    order = list(_TO_MANO_ORDER[:NUM_JOINTS if with_tips else NUM_MANO_JOINTS])
    global_rotations = torch.cat(rotations, dim=1)[:, order[:NUM_MANO_JOINTS]]
    return global_rotations, torch.cat(positions, dim=1)[:, order]


def offsets_from_positions(positions: torch.Tensor) -> torch.Tensor:
    """Turn rest joint positions (B, 16 or 21, 3) into offsets from each joint's parent.

    Entry 0 keeps the root position, so ``forward_kinematics`` with identity rotations returns
    ``positions`` again.
    """
    count = positions.shape[1]
    parents = [max(parent, 0) for parent in PARENTS_WITH_TIPS[:count]]
    offsets = positions - positions[:, parents]
    return torch.cat([positions[:, :1], offsets[:, 1:]], dim=1)
