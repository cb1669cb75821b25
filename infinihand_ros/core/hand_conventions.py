"""Hand conventions shared by every module: sides, joint orders and index maps.

The project's 21-joint order is OpenPose/MediaPipe: 0 wrist; 1-4 thumb (CMC, MCP, IP, tip);
5-8 index (MCP, PIP, DIP, tip); 9-12 middle; 13-16 ring; 17-20 pinky.
MANO's internal 16-joint order is 0 wrist, 1-3 index, 4-6 middle, 7-9 pinky, 10-12 ring,
13-15 thumb (proximal to distal); with the 5 fingertips appended as 16-20 (thumb, index, middle,
ring, pinky) it maps to OpenPose with ``MANO_TO_OPENPOSE``.
"""

from typing import Final

LEFT: Final = 0
RIGHT: Final = 1
SIDES: Final = (LEFT, RIGHT)
SIDE_NAMES: Final = ('left', 'right')

NUM_JOINTS: Final = 21
NUM_MANO_JOINTS: Final = 16
NUM_HAND_POSE_JOINTS: Final = 15
NUM_BETAS: Final = 10
WRIST: Final = 0
#: The middle finger's knuckle: with the wrist, the hand's long axis.
MIDDLE_MCP: Final = 9

JOINT_NAMES: Final = (
    'wrist',
    'thumb_cmc', 'thumb_mcp', 'thumb_ip', 'thumb_tip',
    'index_mcp', 'index_pip', 'index_dip', 'index_tip',
    'middle_mcp', 'middle_pip', 'middle_dip', 'middle_tip',
    'ring_mcp', 'ring_pip', 'ring_dip', 'ring_tip',
    'pinky_mcp', 'pinky_pip', 'pinky_dip', 'pinky_tip',
)

#: Parent of each joint in the 21-joint order (-1 for the wrist).
JOINT_PARENTS: Final = (-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19)

FINGER_NAMES: Final = ('thumb', 'index', 'middle', 'ring', 'pinky')
#: Joint indices of each finger (proximal to tip) in the 21-joint order.
FINGER_JOINTS: Final = tuple(tuple(range(1 + 4 * f, 5 + 4 * f)) for f in range(5))

MANO_JOINT_NAMES: Final = (
    'wrist',
    'index1', 'index2', 'index3',
    'middle1', 'middle2', 'middle3',
    'pinky1', 'pinky2', 'pinky3',
    'ring1', 'ring2', 'ring3',
    'thumb1', 'thumb2', 'thumb3',
)
#: Parent of each MANO joint in MANO's 16-joint order (-1 for the wrist).
MANO_PARENTS: Final = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)
#: Fingertip order appended after the 16 MANO joints (indices 16-20).
MANO_TIP_NAMES: Final = ('thumb_tip', 'index_tip', 'middle_tip', 'ring_tip', 'pinky_tip')
#: Standard MANO fingertip vertex ids (smplx ``vertex_ids['mano']``), same order as the tips.
MANO_TIP_VERTEX_IDS: Final = (744, 320, 443, 554, 671)
#: ``openpose_joints = mano_joints_with_tips[MANO_TO_OPENPOSE]``.
MANO_TO_OPENPOSE: Final = (
    0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20)
#: ``mano_joints_with_tips = openpose_joints[OPENPOSE_TO_MANO]`` (inverse permutation).
OPENPOSE_TO_MANO: Final = tuple(MANO_TO_OPENPOSE.index(i) for i in range(NUM_JOINTS))

#: Palm joints used to estimate the wrist frame (wrist, index MCP, middle MCP).
WRIST_FRAME_JOINTS: Final = (0, 5, 9)


def side_name(side: int) -> str:
    """Return 'left' or 'right' for a side index.

    Raises:
        ValueError: if ``side`` is not 0 (left) or 1 (right).

    """
    if side not in SIDES:
        raise ValueError(f'hand side must be 0 (left) or 1 (right), got {side!r}')
    return SIDE_NAMES[side]


def side_from_name(name: str) -> int:
    """Return the side index of 'left' or 'right' (case-insensitive).

    Raises:
        ValueError: for any other name.

    """
    key = name.strip().lower()
    if key not in SIDE_NAMES:
        raise ValueError(f"hand side must be 'left' or 'right', got {name!r}")
    return SIDE_NAMES.index(key)
