"""Anatomical plausibility of annotated hands: bone lengths and joint bend angles.

Used by the cleaning step to leave implausible annotations out before the 2D comparison
(paper Sec. 3.1). The checks work on 3D joints, so they apply to every dataset alike.
"""

from dataclasses import dataclass

from infinihand_ros.core.config import require_positive
from infinihand_ros.core.hand_conventions import JOINT_PARENTS
import numpy as np

#: Bone b runs from joint ``JOINT_PARENTS[b + 1]`` to joint ``b + 1`` (every joint but the wrist).
_CHILDREN = np.arange(1, len(JOINT_PARENTS))
_PARENTS = np.array(JOINT_PARENTS[1:])
#: Joints where a finger bends: the bone into them and the bone out of them, as bone indices.
_BEND_BONES = np.array([(joint - 1, joint) for joint in _CHILDREN[:-1]
                        if JOINT_PARENTS[joint + 1] == joint])


@dataclass(frozen=True)
class PlausibilityConfig:
    """Limits of a plausible hand (``config/corpus.yaml``, ``cleaning.plausibility``).

    Attributes:
        min_bone_m: shortest plausible bone (m).
        max_bone_m: longest plausible bone (wrist to MCP included, m).
        max_bend_deg: largest angle between consecutive finger bones (0 = straight).

    """

    min_bone_m: float = 0.008
    max_bone_m: float = 0.13
    max_bend_deg: float = 130.0

    def __post_init__(self) -> None:
        require_positive('plausibility', min_bone_m=self.min_bone_m,
                         max_bone_m=self.max_bone_m, max_bend_deg=self.max_bend_deg)


def plausible_hands(joints: np.ndarray, config: PlausibilityConfig) -> np.ndarray:
    """Return which hands (...,) of joints (..., 21, 3) in metres pass every check."""
    points = np.asarray(joints, np.float64)
    bones = points[..., _CHILDREN, :] - points[..., _PARENTS, :]
    lengths = np.linalg.norm(bones, axis=-1)
    length_ok = np.all((lengths >= config.min_bone_m) & (lengths <= config.max_bone_m), axis=-1)
    inbound = bones[..., _BEND_BONES[:, 0], :]
    outbound = bones[..., _BEND_BONES[:, 1], :]
    with np.errstate(invalid='ignore', divide='ignore'):
        cosine = np.einsum('...i,...i->...', inbound, outbound) / (
            np.linalg.norm(inbound, axis=-1) * np.linalg.norm(outbound, axis=-1))
    bend_deg = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    bend_ok = np.all(bend_deg <= config.max_bend_deg, axis=-1)
    return np.all(np.isfinite(points), axis=(-2, -1)) & length_ok & bend_ok
