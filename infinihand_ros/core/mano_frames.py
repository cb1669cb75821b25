"""Moving MANO parameters between frames (hand, camera, world) under rigid transforms.

MANO rotates the hand about its root joint ``J0(betas)`` (the wrist at rest) and then adds
``transl``: ``joints = R_go (J_rest - J0) + J0 + transl``. Mapping every joint by ``x -> R x + t``
therefore gives ``global_orient' = R R_go`` and ``transl' = R (J0 + transl) + t - J0``. For the
built-in hand ``J0 = 0`` and this is exactly the paper's eq. 6 and eq. 9.
"""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.validation import as_array
import numpy as np


def transform_mano_params(params: ManoParams, rotation: np.ndarray, translation: np.ndarray,
                          root_joint: np.ndarray | None = None) -> ManoParams:
    """Express MANO parameters in another frame: every joint maps by ``x -> R x + t``.

    Args:
        params: MANO parameters in the source frame.
        rotation: (3, 3) rotation R from the source to the target frame.
        translation: (3,) translation t from the source to the target frame (m).
        root_joint: (3,) MANO's rest root joint ``J0(betas)``; zero (the built-in hand) if None.

    Returns:
        The same hand in the target frame (hand_pose and betas unchanged).

    """
    rot = as_array(rotation, 'rotation', (3, 3))
    trans = as_array(translation, 'translation', (3,))
    root = np.zeros(3) if root_joint is None else as_array(root_joint, 'root_joint', (3,))
    orient = geometry.matrix_to_axis_angle(
        rot @ geometry.axis_angle_to_matrix(params.global_orient))
    return ManoParams(global_orient=orient, hand_pose=params.hand_pose, betas=params.betas,
                      transl=rot @ (root + params.transl) + trans - root)
