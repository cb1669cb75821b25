"""Moving MANO parameters between frames agrees with moving the joints the model produces."""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.mano.builtin import BuiltinHandModel
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
import torch


def _joints(model: BuiltinHandModel, params: ManoParams, root: np.ndarray) -> np.ndarray:
    """Joints of ``params`` for a model whose rest root joint sits at ``root``."""
    with torch.no_grad():
        out = model(*(torch.as_tensor(v)[None] for v in (
            params.global_orient, params.hand_pose, params.betas, params.transl)))
    # A model rotating about ``root`` = the built-in one (root at 0) moved by ``root``
    # before and after the global rotation: R (J - root) + root + transl.
    rotation = geometry.axis_angle_to_matrix(params.global_orient)
    return out.joints[0].numpy() + root - rotation @ root


@pytest.mark.parametrize('with_root', [False, True])
def test_transformed_params_give_transformed_joints(
        rng: np.random.Generator, with_root: bool) -> None:
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    params = ManoParams(global_orient=rng.normal(size=3), hand_pose=rng.normal(0, 0.2, (15, 3)),
                        betas=rng.normal(size=10), transl=rng.normal(size=3))
    root = rng.normal(0, 0.05, size=3) if with_root else np.zeros(3)
    rotation = Rotation.random(random_state=1).as_matrix()
    translation = rng.normal(size=3)
    moved = transform_mano_params(params, rotation, translation,
                                  root if with_root else None)
    expected = geometry.transform_points(geometry.make_transform(rotation, translation),
                                         _joints(model, params, root))
    np.testing.assert_allclose(_joints(model, moved, root), expected, atol=1e-9)
    np.testing.assert_array_equal(moved.hand_pose, params.hand_pose)
    np.testing.assert_array_equal(moved.betas, params.betas)
