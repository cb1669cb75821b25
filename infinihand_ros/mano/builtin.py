"""The built-in hand skeleton: MANO's kinematic tree with our own anthropometric rest pose.

The licensed MANO files cannot ship with the project, so this module is the default hand model.
It has MANO's 16 joints (wrist; index, middle, pinky, ring, thumb chains of three) plus five
fingertips, MANO's parameters (axis-angle ``global_orient`` and ``hand_pose`` relative to the flat
hand, 10 ``betas``, ``transl``) and MANO's rotation convention (every joint frame is aligned with
the canonical axes at rest), so flexion is mostly about +z for the fingers as in MANO.

Rest pose (right hand, betas = 0): a flat hand with the wrist joint at the origin, fingers along
-x, the palm facing -y (back of the hand +y) and the thumb towards +z. The wrist and the four
fingers lie in the plane y = 0. The thumb does not: its base (CMC) sits 10 mm palmar of that plane
and its ray is abducted 40 degrees from -x towards +z and tilted 15 degrees towards the palm, as a
relaxed thumb rests in front of the palm rather than in it. Because the rest wrist is at the
origin, the output wrist joint equals ``transl`` (real MANO puts it at ``J0(betas) + transl``).

Measurements used (metres, joint centre to joint centre, rounded):

- Phalanx lengths: the mean radiographic lengths of Buryanov & Kotiuk (2010), "Proportions of hand
  segments", Int. J. Morphol. 28(3):755-758 (proximal, middle, distal; mm): index 39.8, 22.4, 15.8;
  middle 44.6, 26.3, 17.4; ring 41.4, 25.7, 17.3; little 32.7, 18.1, 16.0; thumb proximal 31.6,
  distal 21.7. Thumb metacarpal 46 mm (usual adult metacarpal I length). Each fingertip adds 3 mm
  of pulp beyond the distal phalanx, since MANO's tip joints are skin vertices.
- Palm: wrist joint to MCP joints 89 / 92 / 87 / 79 mm (index / middle / ring / little), chosen so
  that wrist-to-middle-tip is 0.183 m, between the adult female (about 0.18 m) and male (about
  0.19 m) mean hand lengths of the US Army survey ANSUR II (Gordon et al. 2014, approximate).
  MCP centres span 58 mm across (z = +26, +6, -13, -32 mm), which with about 11 mm of bone and
  soft tissue on each side gives the surveyed adult hand breadth of about 0.08 m. Thumb CMC at
  (-25, -10, +20) mm from the wrist.
- Finger splay in the flat hand (degrees towards the thumb): index 4, middle 0, ring -4, little -9,
  smaller than the maximal abduction angles measured by Chatzioglou, Pinar & Govsa (2024), Anat.
  Cell Biol. 57(2):172-182 (index-middle 17.2, middle-ring 14.3, ring-little 32.1).

Shape space: each beta scales groups of bone offsets by ``exp(beta * s)`` per axis, so betas = 0 is
the mean hand, one unit is about one population standard deviation, and bone lengths change
monotonically with each beta:

====  ==============================================  =====================================
beta  effect                                          s per unit (about 1 SD)
====  ==============================================  =====================================
0     overall size, every bone                        +5 % (hand length CV about 5 %)
1     palm length (x of wrist-to-MCP/CMC offsets)     +3 %
2     palm breadth (z of wrist-to-MCP/CMC offsets)    +4 %
3     length of the four fingers' phalanges           +3 %
4     thumb length (metacarpal and phalanges)         +4 %
5     index finger length                             +2.5 %
6     ring finger length                              +2.5 %
7     little finger length                            +3.5 %
8     proximal vs distal phalanges (four fingers)     proximal +2 %, distal -2 %
9     thumb base offset (wrist to thumb CMC)          +5 %
====  ==============================================  =====================================

The left hand is the exact mirror image of the right one (see ``mirror.py``): its rest offsets
have x negated, and ``left(go, hp, b, t) = mirror(right(mirror_aa(go), mirror_aa(hp), b,
mirror_pt(t)))``.
"""

import math
from types import MappingProxyType
from typing import Final

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import MANO_JOINT_NAMES
from infinihand_ros.core.hand_conventions import MANO_TIP_NAMES
from infinihand_ros.core.hand_conventions import MANO_TO_OPENPOSE
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import side_name
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.base import HandModelOutput
from infinihand_ros.mano.kinematics import CHAIN_LEVELS
from infinihand_ros.mano.kinematics import forward_kinematics
from infinihand_ros.mano.mirror import mirror_points
import numpy as np
import roma
import torch

_MM: Final = 1e-3
#: Names of the 21 MANO joints with tips, in MANO order (tips appended as 16-20).
JOINT_NAMES_WITH_TIPS: Final = MANO_JOINT_NAMES + MANO_TIP_NAMES

#: Soft tissue beyond the distal phalanx up to the fingertip skin (m).
FINGERTIP_PULP_M: Final = 3.0 * _MM
#: Wrist-to-MCP joint position (x, z) of each long finger in the palm plane y = 0 (m).
FINGER_MCP_XZ_M: Final = MappingProxyType({
    'index': (-89.0 * _MM, 26.0 * _MM),
    'middle': (-92.0 * _MM, 6.0 * _MM),
    'ring': (-87.0 * _MM, -13.0 * _MM),
    'pinky': (-79.0 * _MM, -32.0 * _MM),
})
#: Splay of each long finger in the flat hand, degrees from -x towards +z (the thumb side).
FINGER_SPLAY_DEG: Final = MappingProxyType(
    {'index': 4.0, 'middle': 0.0, 'ring': -4.0, 'pinky': -9.0})
#: Bone lengths after the first joint of each chain (m): the two phalanges between the chain's
#: joints, then the last bone to the tip (pulp excluded). Buryanov & Kotiuk 2010 (see above).
CHAIN_BONE_LENGTHS_M: Final = MappingProxyType({
    'index': (39.8 * _MM, 22.4 * _MM, 15.8 * _MM),
    'middle': (44.6 * _MM, 26.3 * _MM, 17.4 * _MM),
    'ring': (41.4 * _MM, 25.7 * _MM, 17.3 * _MM),
    'pinky': (32.7 * _MM, 18.1 * _MM, 16.0 * _MM),
    'thumb': (46.0 * _MM, 31.6 * _MM, 21.7 * _MM),
})
#: Thumb CMC joint (MANO 'thumb1') relative to the wrist (m); palmar of the plane y = 0.
THUMB_CMC_M: Final = (-25.0 * _MM, -10.0 * _MM, 20.0 * _MM)
#: Thumb ray at rest: abduction from -x towards +z, then tilt towards the palm (-y), degrees.
THUMB_ABDUCTION_DEG: Final = 40.0
THUMB_PALMAR_TILT_DEG: Final = 15.0

_ALL_AXES: Final = (0, 1, 2)
_X_AXIS: Final = (0,)
_Z_AXIS: Final = (2,)
_LONG_FINGERS: Final = ('index', 'middle', 'ring', 'pinky')
#: Name suffixes of each chain's second and third joints and of its tip.
_PROXIMAL_SUFFIX, _MIDDLE_SUFFIX, _TIP_SUFFIX = '2', '3', '_tip'


def _joints(*names: str) -> tuple[int, ...]:
    """Return the indices of the named joints in ``JOINT_NAMES_WITH_TIPS``."""
    return tuple(JOINT_NAMES_WITH_TIPS.index(name) for name in names)


def _chain_bones(*fingers: str) -> tuple[int, ...]:
    """Return the joints whose offsets are the bones after the first joint of the chains."""
    return _joints(*(finger + suffix for finger in fingers
                     for suffix in (_PROXIMAL_SUFFIX, _MIDDLE_SUFFIX, _TIP_SUFFIX)))


#: Shape space: (beta index, joints whose offsets scale, axes, log-scale per unit beta).
SHAPE_EFFECTS: Final = (
    (0, tuple(range(1, NUM_JOINTS)), _ALL_AXES, 0.05),
    (1, CHAIN_LEVELS[0], _X_AXIS, 0.03),
    (2, CHAIN_LEVELS[0], _Z_AXIS, 0.04),
    (3, _chain_bones(*_LONG_FINGERS), _ALL_AXES, 0.03),
    (4, _chain_bones('thumb'), _ALL_AXES, 0.04),
    (5, _chain_bones('index'), _ALL_AXES, 0.025),
    (6, _chain_bones('ring'), _ALL_AXES, 0.025),
    (7, _chain_bones('pinky'), _ALL_AXES, 0.035),
    (8, _joints(*(f + _PROXIMAL_SUFFIX for f in _LONG_FINGERS)), _ALL_AXES, 0.02),
    (8, _joints(*(f + _TIP_SUFFIX for f in _LONG_FINGERS)), _ALL_AXES, -0.02),
    (9, _joints('thumb1'), _ALL_AXES, 0.05),
)


def _direction(abduction_deg: float, palmar_tilt_deg: float = 0.0) -> np.ndarray:
    """Return -x turned towards +z by the abduction, then towards -y (palm) by the tilt."""
    abduction, tilt = math.radians(abduction_deg), math.radians(palmar_tilt_deg)
    return np.array([-math.cos(abduction) * math.cos(tilt), -math.sin(tilt),
                     math.sin(abduction) * math.cos(tilt)])


def rest_offsets(side: int) -> np.ndarray:
    """Rest offsets of the mean hand: (21, 3) float64 metres, MANO order with tips.

    Entry 0 is the wrist (the origin); entry i is joint i minus its parent at rest.

    Raises:
        ValueError: for a side other than 0 (left) or 1 (right).

    """
    side_name(side)
    offsets = np.zeros((NUM_JOINTS, 3))
    chain_specs = {finger: (np.array([x, 0.0, z]), _direction(FINGER_SPLAY_DEG[finger]))
                   for finger, (x, z) in FINGER_MCP_XZ_M.items()}
    chain_specs['thumb'] = (np.array(THUMB_CMC_M),
                            _direction(THUMB_ABDUCTION_DEG, THUMB_PALMAR_TILT_DEG))
    for finger, (base, direction) in chain_specs.items():
        lengths = np.array(CHAIN_BONE_LENGTHS_M[finger]) + np.array([0.0, 0.0, FINGERTIP_PULP_M])
        offsets[_joints(finger + '1')[0]] = base
        for joint, length in zip(_chain_bones(finger), lengths):
            offsets[joint] = length * direction
    return mirror_points(offsets) if side == LEFT else offsets


def shape_log_scales() -> np.ndarray:
    """Log-scale of each offset axis per unit beta: (10, 21, 3) float64 (see ``SHAPE_EFFECTS``)."""
    scales = np.zeros((NUM_BETAS, NUM_JOINTS, 3))
    for beta, joints, axes, log_scale in SHAPE_EFFECTS:
        scales[np.ix_([beta], list(joints), list(axes))] += log_scale
    return scales


class BuiltinHandModel(HandModel):
    """Differentiable, batched forward kinematics of the built-in skeleton.

    Computation runs in the dtype and device of the module's buffers (the constructor's ``dtype``,
    or torch's default; ``.to(device)`` works like for any module). Inputs are converted to it.
    """

    def __init__(self, side: int, dtype: torch.dtype | None = None) -> None:
        """Build the model of one side.

        Args:
            side: 0 left, 1 right.
            dtype: dtype of the buffers (default: torch's default dtype).

        Raises:
            ValueError: for a side other than 0 or 1.

        """
        super().__init__(side)
        dtype = dtype or torch.get_default_dtype()
        self.register_buffer('rest_offsets', torch.as_tensor(rest_offsets(side), dtype=dtype))
        self.register_buffer('shape_log_scales',
                             torch.as_tensor(shape_log_scales(), dtype=dtype))
        self.register_buffer('to_openpose', torch.as_tensor(MANO_TO_OPENPOSE, dtype=torch.long),
                             persistent=False)

    def bone_offsets(self, betas: torch.Tensor) -> torch.Tensor:
        """Rest offsets (B, 21, 3) in metres for shape coefficients ``betas`` (B, 10)."""
        log_scale = torch.einsum('bk,kjc->bjc', betas, self.shape_log_scales)
        return self.rest_offsets * torch.exp(log_scale)

    def _forward_checked(self, global_orient: torch.Tensor, hand_pose: torch.Tensor,
                         betas: torch.Tensor, transl: torch.Tensor) -> HandModelOutput:
        axis_angles = torch.cat([global_orient[:, None], hand_pose], dim=1)
        local_rotations = roma.rotvec_to_rotmat(axis_angles)
        global_rotations, positions = forward_kinematics(local_rotations, self.bone_offsets(betas))
        joints = positions[:, self.to_openpose] + transl[:, None]
        return HandModelOutput(joints=joints, global_rotations=global_rotations, vertices=None)


def canonical_joints(side: int) -> np.ndarray:
    """Joints of the built-in mean hand at zero pose, root-relative: (21, 3) float64 metres.

    OpenPose order, wrist at the origin (zero pose, shape, orientation and translation); used for
    the metrics' missed-hand penalties.

    Raises:
        ValueError: for a side other than 0 or 1.

    """
    model = BuiltinHandModel(side, dtype=torch.float64)
    with torch.no_grad():
        out = model(torch.zeros(1, 3), torch.zeros(1, NUM_HAND_POSE_JOINTS, 3),
                    torch.zeros(1, NUM_BETAS), torch.zeros(1, 3))
    joints = out.joints[0].numpy()
    return joints - joints[WRIST]
