"""Small SE(3) helpers for the BA solver: skew matrices, the left retraction, adjoints.

Twists are ordered ``xi = (v, omega)`` (translation, rotation), radians and metres. The solver
perturbs world-to-camera poses ``G`` on the left: ``G <- Exp(xi) G``.
"""

import numpy as np
from scipy.spatial.transform import Rotation


def skew(vectors: np.ndarray) -> np.ndarray:
    """Return the cross-product matrices (..., 3, 3) of vectors (..., 3)."""
    v = np.asarray(vectors, dtype=np.float64)
    zero = np.zeros(v.shape[:-1])
    return np.stack([np.stack([zero, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], zero, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], zero], -1)], -2)


def retract(rotation: np.ndarray, translation: np.ndarray,
            twist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply left increments to world-to-camera poses.

    ``R <- Exp(omega) R``, ``t <- Exp(omega) t + v``: equal to ``Exp(xi) G`` to first order, with
    the derivative ``d(G X)/d xi = [I, -[G X]x]`` that the solver's Jacobians use.

    Args:
        rotation: (F, 3, 3) rotations of the poses.
        translation: (F, 3) translations of the poses (m).
        twist: (F, 6) increments (v, omega).

    Returns:
        The new (rotation (F, 3, 3), translation (F, 3)).

    """
    delta = Rotation.from_rotvec(twist[:, 3:]).as_matrix()
    return delta @ rotation, np.einsum('fij,fj->fi', delta, translation) + twist[:, :3]


def adjoint(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Return the (..., 6, 6) adjoints of poses (R, t) for twists ordered (v, omega)."""
    out = np.zeros(rotation.shape[:-2] + (6, 6))
    out[..., :3, :3] = rotation
    out[..., :3, 3:] = skew(translation) @ rotation
    out[..., 3:, 3:] = rotation
    return out


def inverse(rotation: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert rigid poses given as (R (..., 3, 3), t (..., 3))."""
    rot_t = np.swapaxes(rotation, -1, -2)
    return rot_t, -np.einsum('...ij,...j->...i', rot_t, translation)
