"""2D landmarks and metric hand-relative joints lifted to a camera-space MANO hand.

The real-image hand source (``mediapipe_source.py``) gives, per hand, 21 pixel landmarks and
21 metric joints relative to the hand (axes along the camera's). ``lift_hand`` turns them into
the hand the paper's branch produces, in three steps:

1. MANO pose and orientation by the project's fitting (``mano/fit.py``): the closed-form
   ``inverse_kinematics`` (bone directions; bone lengths are the hand model's for the hand's
   betas, so one person keeps one shape), optionally refined by ``fit_mano`` warm-started
   there;
2. the root depth ``t_z`` and lateral translation: for each candidate depth the paper's eq. 5
   least-squares projection (``model/hand/lsp.py``, here in numpy) gives ``(t_x, t_y)``; the
   depth minimising the mean pixel error is found by a grid search refined twice (the hand's
   metric size fixes it);
3. a ``HandState`` in camera space: MANO parameters with that translation, joints, the
   landmarks as 2D joints, the landmark box, and the source's confidence.

Everything runs in numpy on one hand's 21 joints (with the float64 built-in skeleton, the hand
model too): torch's cost per call would be most of the time.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.geometry import MIN_PROJECTION_DEPTH_M
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.fit import fit_mano
from infinihand_ros.mano.fit import inverse_kinematics
from infinihand_ros.mano.fit import ManoFitConfig
from infinihand_ros.mano.fit import model_joints
from infinihand_ros.mano.fit import rest_joints
import numpy as np

#: Root depths searched, metres (hands from touching the lens to across a room).
DEPTH_RANGE_M: Final = (0.05, 5.0)
#: Depths per grid of the root-depth search, and finer grids after the first.
DEPTH_GRID: Final = 48
DEPTH_REFINEMENTS: Final = 2
#: Smallest eq. 5 denominator treated as "no joint in front of the camera" (as in lsp.py).
_MIN_DENOMINATOR: Final = 1e-12
#: The first grid of root depths, log-spaced over ``DEPTH_RANGE_M``.
_FIRST_DEPTHS: Final = np.exp(np.linspace(np.log(DEPTH_RANGE_M[0]), np.log(DEPTH_RANGE_M[1]),
                                          DEPTH_GRID))


@dataclass(frozen=True)
class LiftedHand:
    """A lifted hand and how well it matches its landmarks.

    Attributes:
        hand: the camera-space hand.
        reprojection_px: mean distance of its projected joints to the landmarks, pixels.
        box_size_px: the landmark box's larger side, pixels.

    """

    hand: HandState
    reprojection_px: float
    box_size_px: float


def place_by_projection(joints_rel: np.ndarray, landmarks_px: np.ndarray,
                        intrinsics: Intrinsics) -> tuple[np.ndarray, float]:
    """Return the translation (3,) putting hand-relative joints on their landmarks, and the error.

    For each root depth eq. 5 gives the lateral translation in closed form; the depth is the
    one with the smallest mean pixel error, searched on a log-spaced grid and refined on finer
    grids around the best (each grid one batched eq. 5 solve).

    Args:
        joints_rel: (21, 3) joints without translation, camera axes, metres.
        landmarks_px: (21, 2) pixels.
        intrinsics: the camera's.

    """
    joints = np.asarray(joints_rel, dtype=np.float64)
    pixels = np.asarray(landmarks_px, dtype=np.float64).T[..., None]  # (2, 21, 1): u, v rows
    lateral_joints = joints[:, :2].T[..., None]
    focal = np.array([intrinsics.fx, intrinsics.fy])[:, None, None]
    centre = np.array([intrinsics.cx, intrinsics.cy])[:, None, None]
    centred = pixels - centre
    depths = _FIRST_DEPTHS
    for _ in range(DEPTH_REFINEMENTS + 1):  # arrays (2, 21, depths): x and y, joint, depth
        count = len(depths)
        z = joints[:, 2:] + depths
        lateral = _lateral_translation(lateral_joints, z, centred, focal)
        projected = focal * (lateral_joints + lateral[:, None]) / np.maximum(z, 1e-9) + centre
        offsets = projected - pixels
        errors = np.hypot(offsets[0], offsets[1]).mean(axis=0)
        best = int(errors.argmin())
        shift = np.array([lateral[0, best], lateral[1, best], depths[best]])
        step = (depths[min(best + 1, count - 1)] - depths[max(best - 1, 0)]) / 2
        depths = np.maximum(np.linspace(depths[best] - step, depths[best] + step, DEPTH_GRID),
                            DEPTH_RANGE_M[0])
    return shift, float(errors[best])


def _lateral_translation(lateral_joints: np.ndarray, z: np.ndarray, centred: np.ndarray,
                         focal: np.ndarray) -> np.ndarray:
    """Return eq. 5's (t_x, t_y) as (2, N): one hand at N root depths.

    ``solve_lateral_translation`` (``model/hand/lsp.py``) in numpy: joints at depths under
    ``MIN_PROJECTION_DEPTH_M`` are left out, and a root depth with none left gets (0, 0).

    Args:
        lateral_joints: (2, J, 1) the translation-free joints' x and y, metres.
        z: (J, N) the joints' depths ``X_z + t_z`` at each root depth, metres.
        centred: (2, J, 1) their landmarks' u and v minus the principal point's.
        focal: (2, 1, 1) f_x, f_y, pixels.

    """
    valid = z > MIN_PROJECTION_DEPTH_M
    gain = focal / np.where(valid, z, 1.0)
    weighted = valid * gain
    numerator = np.einsum('cjn,cjn->cn', weighted, centred - gain * lateral_joints)
    denominator = np.einsum('cjn,cjn->cn', weighted, gain)
    solvable = denominator > _MIN_DENOMINATOR
    return np.where(solvable, numerator / np.where(solvable, denominator, 1.0), 0.0)


def lift_hand(side: int, landmarks_px: np.ndarray, joints_metric: np.ndarray,
              confidence: float, intrinsics: Intrinsics, model: HandModel,
              previous: ManoParams | None = None, refine_iterations: int = 0,
              ray_passes: int = 2) -> LiftedHand:
    """Return the camera-space MANO hand of one detection.

    Args:
        side: 0 left, 1 right (our convention).
        landmarks_px: (21, 2) landmarks in the image of ``intrinsics``, OpenPose order.
        joints_metric: (21, 3) metric hand-relative joints, camera axes, OpenPose order.
        confidence: the source's score in [0, 1].
        intrinsics: the intrinsics of the image (given, fallback or predicted).
        model: the hand model of ``side``.
        previous: the same hand's parameters in the previous frame: its shape is kept (the
            pose needs no start: the closed-form fit is this frame's own).
        refine_iterations: L-BFGS steps of ``fit_mano`` after the closed-form start (0: none).
        ray_passes: passes turning the bones towards the landmarks' viewing rays at the depths
            found (each kept only if it lowers the pixel error): MediaPipe's metric joints give
            the pose, its 2D landmarks refine it.

    """
    betas = None if previous is None else previous.betas
    rest = rest_joints(model, betas)
    params = inverse_kinematics(model, joints_metric, betas, rest)
    if refine_iterations > 0:
        fitted = fit_mano(model, joints_metric[None],
                          config=ManoFitConfig(iterations=refine_iterations), initial=params)
        params = ManoParams(fitted.global_orient[0], fitted.hand_pose[0], fitted.betas[0],
                            fitted.transl[0])
        rest = rest_joints(model, params.betas)
    relative = model_joints(model, params) - params.transl
    shift, error_px = place_by_projection(relative, landmarks_px, intrinsics)
    for _ in range(ray_passes):  # bones towards the landmarks' rays at the depths found
        rays = _back_project(landmarks_px, (relative + shift)[:, 2], intrinsics)
        candidate = inverse_kinematics(model, rays, params.betas, rest)
        moved = model_joints(model, candidate) - candidate.transl
        moved_shift, moved_error = place_by_projection(moved, landmarks_px, intrinsics)
        if moved_error >= error_px:
            break
        params, relative, shift, error_px = candidate, moved, moved_shift, moved_error
    mano = ManoParams(params.global_orient, params.hand_pose, params.betas, shift)
    low, high = landmarks_px.min(axis=0), landmarks_px.max(axis=0)
    hand = HandState(side, mano, relative + shift, np.asarray(landmarks_px, dtype=np.float64),
                     np.concatenate([low, high]), float(np.clip(confidence, 0.0, 1.0)))
    return LiftedHand(hand, error_px, float(np.max(high - low)))


def _back_project(pixels: np.ndarray, depths: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Return (21, 3) camera-frame points on the pixels' rays at the given depths."""
    x = (pixels[:, 0] - intrinsics.cx) / intrinsics.fx
    y = (pixels[:, 1] - intrinsics.cy) / intrinsics.fy
    return np.stack([x * depths, y * depths, depths], axis=1)
