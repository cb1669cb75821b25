"""MANO fitting to 3D keypoints (paper Sec. 3.1: where a dataset has only 3D hand keypoints).

``fit_mano`` fits pose, shape, global orientation and translation of any ``HandModel`` (the
built-in skeleton or real MANO) to a sequence of (T, 21, 3) keypoints with per-joint validity,
all frames in one batch. The objective, in millimetres so the weights read naturally, is

    mean over valid joints of |J(theta_t) - K_t|^2
    + smoothness_weight * mean |L_{t+1} - 2 L_t + L_{t-1}|^2   (L: joints minus the wrist)
    + pose_prior_weight * mean |hand_pose|^2 + betas_prior_weight * mean |betas|^2.

The acceleration term carries the fit through frames without keypoints and damps keypoint
noise; the small priors pick one solution where joints do not determine it (a finger's twist
about its own bone). Orientation and translation start from a rigid (Kabsch) fit of the rest
palm to the keypoints, then L-BFGS refines everything. One shape per sequence by default (one
person per hand track).

``inverse_kinematics`` is the fast start for live use: the palm's rigid fit gives the wrist
orientation, then, level by level down each finger, every joint gets the smallest rotation that
turns its rest bone (as its parent now holds it) onto the keypoints' bone. It needs no
iteration (well under a millisecond per frame); ``fit_mano(..., initial=...)`` then refines
shape and twist in a few L-BFGS steps. For one frame's hand ``model_joints`` and ``rest_joints``
pose the float64 built-in skeleton in numpy: torch's cost per call would dominate.
"""

from collections.abc import Sequence
import copy
from dataclasses import dataclass
import time
from typing import Final

from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import axis_angle_to_matrix
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.core.hand_conventions import OPENPOSE_TO_MANO
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.kinematics import CHAIN_LEVELS
from infinihand_ros.mano.kinematics import CHAIN_TIPS
from infinihand_ros.mano.kinematics import PARENTS_WITH_TIPS
import numpy as np
import roma
from scipy.spatial.transform import Rotation
import torch

#: Palm joints (wrist, MCPs of index, middle, ring, pinky) used for the rigid initialisation.
PALM_JOINTS: Final = (0, 5, 9, 13, 17)
_M_TO_MM: Final = 1000.0
#: The palm joints' MANO indices.
_PALM_MANO: Final = np.array([OPENPOSE_TO_MANO.index(joint) for joint in PALM_JOINTS])
#: The joints below the wrist by depth (the chains' levels, then the tips), each as (MANO
#: indices with tips, their parents' indices).
_LEVELS: Final = tuple((np.array(level), np.array([PARENTS_WITH_TIPS[j] for j in level]))
                       for level in CHAIN_LEVELS + (CHAIN_TIPS,))
#: The finger bones, MANO indices with tips, as (levels, chains) arrays: each bone's joint and
#: the joint's child.
_BONE_STARTS: Final = np.array(CHAIN_LEVELS)
_BONE_ENDS: Final = np.array(CHAIN_LEVELS[1:] + (CHAIN_TIPS,))
#: Cyclic axis orders (y, z, x) and (z, x, y) of a cross product.
_NEXT_AXIS: Final = np.array([1, 2, 0])
_LAST_AXIS: Final = np.array([2, 0, 1])
#: Axis-angle of the tips' local rotations (they turn nothing), and the rest pose's rotations.
_TIP_ROTATIONS: Final = np.zeros((NUM_JOINTS - NUM_MANO_JOINTS, 3))
_REST_ROTATIONS: Final = np.broadcast_to(np.eye(3), (NUM_JOINTS, 3, 3))


@dataclass(frozen=True)
class ManoFitConfig:
    """Settings of the keypoint fit (``config/corpus.yaml``, section ``mano_fit``).

    Attributes:
        iterations: L-BFGS iterations (each with a strong-Wolfe line search).
        history: L-BFGS history size.
        shared_betas: one shape for the whole sequence (else one per frame).
        smoothness_weight: weight of the joint-acceleration term (per mm^2 of acceleration).
        pose_prior_weight: weight of the hand-pose prior (mm^2 per rad^2).
        betas_prior_weight: weight of the shape prior (mm^2 per unit^2).
        tolerance_mm: stop when the RMS step of the joints falls below this (mm).

    """

    iterations: int = 200
    history: int = 100
    shared_betas: bool = True
    smoothness_weight: float = 0.05
    pose_prior_weight: float = 0.01
    betas_prior_weight: float = 0.01
    tolerance_mm: float = 1e-4

    def __post_init__(self) -> None:
        require_at_least('mano_fit', 1, iterations=self.iterations, history=self.history)
        require_at_least('mano_fit', 0.0, smoothness_weight=self.smoothness_weight,
                         pose_prior_weight=self.pose_prior_weight,
                         betas_prior_weight=self.betas_prior_weight,
                         tolerance_mm=self.tolerance_mm)


@dataclass(frozen=True)
class ManoFitResult:
    """Fitted parameters and residuals of one hand track (float64, T frames).

    Attributes:
        global_orient: (T, 3) axis-angle, frame of the keypoints.
        hand_pose: (T, 15, 3) axis-angle, flat-hand relative.
        betas: (T, 10) shape (the same row in every frame with ``shared_betas``).
        transl: (T, 3) metres.
        joints: (T, 21, 3) fitted joints, metres, frame of the keypoints.
        joint_errors_mm: (T, 21) distance fitted-to-keypoint, NaN where the joint was invalid.
        frame_errors_mm: (T,) mean of the valid joint errors, NaN for frames without any.
        iterations: L-BFGS iterations run.
        seconds: wall time of the fit.

    """

    global_orient: np.ndarray
    hand_pose: np.ndarray
    betas: np.ndarray
    transl: np.ndarray
    joints: np.ndarray
    joint_errors_mm: np.ndarray
    frame_errors_mm: np.ndarray
    iterations: int
    seconds: float

    @property
    def frames_per_second(self) -> float:
        """Frames fitted per second of wall time."""
        return len(self.joints) / max(self.seconds, 1e-9)


def _check_inputs(keypoints: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """Return (keypoints (T, 21, 3) float64 with invalid joints zeroed, valid (T, 21) bool)."""
    points = np.asarray(keypoints, dtype=np.float64)
    if points.ndim != 3 or points.shape[1:] != (NUM_JOINTS, 3) or len(points) == 0:
        raise InputError(f'keypoints: expected shape (T, {NUM_JOINTS}, 3) with T >= 1, got '
                         f'{points.shape}')
    mask = np.ones(points.shape[:2], bool) if valid is None else np.asarray(valid, bool)
    if mask.shape != points.shape[:2]:
        raise InputError(f'valid: expected shape {points.shape[:2]}, got {mask.shape}')
    mask = mask & np.all(np.isfinite(points), axis=-1)
    return np.where(mask[..., None], points, 0.0), mask


def _rigid_init(model: HandModel, points: torch.Tensor,
                valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Orientation (T, 3) and translation (T, 3) aligning the rest palm with the keypoints.

    Frames with fewer than three valid palm joints take the nearest frame that has them (or the
    identity at the keypoints' mean when no frame has).
    """
    frames = points.shape[0]
    zeros = points.new_zeros
    rest = model(zeros(1, 3), zeros(1, NUM_HAND_POSE_JOINTS, 3), zeros(1, NUM_BETAS),
                 zeros(1, 3)).joints[0]
    palm = list(PALM_JOINTS)
    weights = valid[:, palm].to(points.dtype)
    usable = (weights.sum(dim=1) >= 3).cpu().numpy()
    rotation = torch.eye(3, dtype=points.dtype).expand(frames, 3, 3).clone()
    shift = points.new_zeros(frames, 3)
    if usable.any():
        index = np.flatnonzero(usable)
        rot, trans = roma.rigid_points_registration(
            rest[palm].expand(len(index), -1, -1), points[index][:, palm],
            weights=weights[index] + 1e-12)
        nearest = index[np.abs(np.arange(frames)[:, None] - index[None]).argmin(axis=1)]
        lookup = {int(i): k for k, i in enumerate(index)}
        picks = [lookup[int(i)] for i in nearest]
        rotation, shift = rot[picks], trans[picks]
    elif valid.any():
        shift = shift + points[valid].mean(dim=0) - rest[0]
    root = rest[0]
    # Model joints are R (P - J0) + J0 + transl; the rigid fit is R P + t.
    transl = shift + torch.einsum('tij,j->ti', rotation, root) - root
    return roma.rotmat_to_rotvec(rotation), transl


def _acceleration(joints: torch.Tensor) -> torch.Tensor:
    """Mean squared second difference over time of wrist-relative (T, 21, 3) joints.

    Wrist-relative, so head and arm motion (often metres per second in the camera frame) are
    not smoothed, only the articulation and orientation; 0 for T < 3.
    """
    if joints.shape[0] < 3:
        return joints.new_zeros(())
    local = joints - joints[:, :1]
    accel = local[2:] - 2.0 * local[1:-1] + local[:-2]
    return (accel * accel).sum(dim=-1).mean()


@dataclass
class _Parameters:
    """Optimisation variables of a track (T frames; translation in mm)."""

    orient: torch.Tensor
    pose: torch.Tensor
    betas: torch.Tensor
    transl_mm: torch.Tensor

    def tensors(self) -> list[torch.Tensor]:
        """Return the variables in a fixed order."""
        return [self.orient, self.pose, self.betas, self.transl_mm]

    def select(self, frames: np.ndarray) -> '_Parameters':
        """Return copies of the variables of ``frames`` (shared betas stay shared)."""
        betas = self.betas if len(self.betas) == 1 else self.betas[frames]
        return _Parameters(self.orient[frames].clone(), self.pose[frames].clone(),
                           betas.clone(), self.transl_mm[frames].clone())


def _joints_mm(model: HandModel, params: _Parameters) -> torch.Tensor:
    """Model joints (T, 21, 3) in millimetres."""
    frames = params.orient.shape[0]
    return model(params.orient, params.pose, params.betas.expand(frames, NUM_BETAS),
                 params.transl_mm / _M_TO_MM).joints * _M_TO_MM


def _solve(model: HandModel, points_mm: torch.Tensor, weight: torch.Tensor,
           params: _Parameters, config: ManoFitConfig) -> int:
    """Minimise the objective over ``params`` in place; return the L-BFGS iterations run."""
    variables = [tensor.requires_grad_(True) for tensor in params.tensors()]
    count = weight.sum().clamp(min=1.0)
    optimizer = torch.optim.LBFGS(variables, lr=1.0, max_iter=config.iterations,
                                  history_size=config.history,
                                  tolerance_change=config.tolerance_mm ** 2,
                                  tolerance_grad=1e-9, line_search_fn='strong_wolfe')

    def objective() -> torch.Tensor:
        optimizer.zero_grad()
        joints = _joints_mm(model, params)
        data = (((joints - points_mm) ** 2).sum(dim=-1) * weight).sum() / count
        loss = (data + config.smoothness_weight * _acceleration(joints)
                + config.pose_prior_weight * (params.pose * params.pose).mean()
                + config.betas_prior_weight * (params.betas * params.betas).mean())
        loss.backward()
        return loss

    optimizer.step(objective)
    for tensor in variables:
        tensor.requires_grad_(False)
    return int(optimizer.state[variables[0]].get('n_iter', 0))


def _fill_gaps(params: _Parameters, fitted: _Parameters, known: np.ndarray) -> None:
    """Write the ``fitted`` variables of the ``known`` frames into ``params``.

    The other frames get them interpolated linearly (held constant beyond the ends).
    """
    frames = np.arange(params.orient.shape[0])
    for target, source in ((params.orient, fitted.orient), (params.pose, fitted.pose),
                           (params.transl_mm, fitted.transl_mm)):
        flat = source.reshape(len(known), -1).cpu().numpy()
        filled = np.stack([np.interp(frames, known, column) for column in flat.T], axis=1)
        target.copy_(torch.as_tensor(filled.reshape(target.shape), dtype=target.dtype))
    if len(params.betas) == 1:
        params.betas.copy_(fitted.betas)
    else:
        params.betas[known] = fitted.betas


def _initial_parameters(model: HandModel, points_mm: torch.Tensor, mask: torch.Tensor,
                        shared_betas: bool, initial: ManoParams | None = None) -> _Parameters:
    """Rigid palm alignment, flat hand and mean shape; or ``initial`` placed on the wrist."""
    frames = points_mm.shape[0]
    with torch.no_grad():
        orient, transl = _rigid_init(model, points_mm / _M_TO_MM, mask)
    if initial is None:
        return _Parameters(orient, points_mm.new_zeros(frames, NUM_HAND_POSE_JOINTS, 3),
                           points_mm.new_zeros(1 if shared_betas else frames, NUM_BETAS),
                           transl * _M_TO_MM)

    def tiled(value: np.ndarray, count: int) -> torch.Tensor:
        tensor = torch.as_tensor(value, dtype=points_mm.dtype, device=points_mm.device)
        return tensor.expand(count, *tensor.shape).clone()

    params = _Parameters(tiled(initial.global_orient, frames), tiled(initial.hand_pose, frames),
                         tiled(initial.betas, 1 if shared_betas else frames),
                         points_mm.new_zeros(frames, 3))
    with torch.no_grad():  # the translation that puts the started hand's wrist on the keypoints
        wrist = _joints_mm(model, params)[:, 0]
        params.transl_mm = points_mm[:, 0] - wrist
    return params


def fit_mano(model: HandModel, keypoints: np.ndarray, valid: np.ndarray | None = None,
             config: ManoFitConfig = ManoFitConfig(), initial: ManoParams | None = None
             ) -> ManoFitResult:
    """Fit the hand model to a track of 3D keypoints.

    The fit runs in the model's dtype and device (float64 gives the most exact fits). When some
    frames have no valid keypoint, the frames that have are fitted first and their parameters
    interpolated into the gaps before the whole track is refined.

    Args:
        model: hand model of the keypoints' side.
        keypoints: (T, 21, 3) joints in metres, OpenPose order, any frame.
        valid: (T, 21) bool, which joints to fit (default: every finite one).
        config: weights and iteration limits.
        initial: parameters to start every frame from (a warm start, e.g. the previous frame's
            fit of the same hand: orientation, pose and shape; the translation comes from the
            rigid palm fit); None: the rigid palm fit, flat hand, mean shape.

    Returns:
        The fitted parameters, joints and per-frame residuals.

    Raises:
        InputError: for keypoints or validity of the wrong shape.

    """
    start = time.perf_counter()
    points_np, valid_np = _check_inputs(keypoints, valid)
    reference = next(model.buffers())
    points = torch.as_tensor(points_np * _M_TO_MM, dtype=reference.dtype, device=reference.device)
    mask = torch.as_tensor(valid_np, device=reference.device)
    weight = mask.to(points.dtype)
    params = _initial_parameters(model, points, mask, config.shared_betas, initial)
    known = np.flatnonzero(valid_np.any(axis=1))
    iterations = 0
    if 0 < len(known) < len(points):
        subset = params.select(known)
        iterations += _solve(model, points[known], weight[known], subset, config)
        with torch.no_grad():
            _fill_gaps(params, subset, known)
    iterations += _solve(model, points, weight, params, config)
    with torch.no_grad():
        joints = _joints_mm(model, params).cpu().numpy().astype(np.float64)
    errors = np.linalg.norm(joints - points_np * _M_TO_MM, axis=-1)
    errors = np.where(valid_np, errors, np.nan)
    counts = valid_np.sum(axis=1)
    frame_errors = np.full(len(points), np.nan)
    frame_errors[counts > 0] = np.nansum(errors, axis=1)[counts > 0] / counts[counts > 0]

    def numpy(tensor: torch.Tensor) -> np.ndarray:
        return tensor.detach().cpu().numpy().astype(np.float64)

    return ManoFitResult(
        global_orient=numpy(params.orient), hand_pose=numpy(params.pose),
        betas=np.broadcast_to(numpy(params.betas), (len(points), NUM_BETAS)).copy(),
        transl=numpy(params.transl_mm) / _M_TO_MM, joints=joints / _M_TO_MM,
        joint_errors_mm=errors, frame_errors_mm=frame_errors, iterations=iterations,
        seconds=time.perf_counter() - start)


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Return vectors (K, 3) scaled to unit length (zero-length ones stay near zero)."""
    return vectors / np.maximum(np.sqrt(np.einsum('ki,ki->k', vectors, vectors)), 1e-12)[:, None]


def _swing(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Smallest rotations (K, 3, 3) turning directions ``source`` onto ``target`` (K, 3)."""
    a, b = _unit(source), _unit(target)
    axis = a[:, _NEXT_AXIS] * b[:, _LAST_AXIS] - a[:, _LAST_AXIS] * b[:, _NEXT_AXIS]  # a x b
    sine = np.sqrt(np.einsum('ki,ki->k', axis, axis))
    angle = np.arctan2(sine, np.einsum('ki,ki->k', a, b))
    unit = axis / np.maximum(sine, 1e-12)[:, None]
    return Rotation.from_rotvec(unit * angle[:, None]).as_matrix()


def _kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Return the rotation (3, 3) best turning centred ``source`` points onto ``target``'s."""
    a = source - source.mean(axis=0)
    b = target - target.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def _posed_in_numpy(model: HandModel) -> bool:
    """Return whether ``model`` is the float64 built-in skeleton, which is posed in numpy."""
    return type(model) is BuiltinHandModel and model.rest_offsets.dtype == torch.float64


def float64_copies(models: Sequence[HandModel]) -> list[HandModel]:
    """Return float64 copies of hand models: the built-in skeleton's are then posed in numpy."""
    return [copy.deepcopy(model).to(torch.float64) for model in models]


def _skeleton_joints(model: BuiltinHandModel, betas: np.ndarray,
                     local: np.ndarray) -> np.ndarray:
    """Return the built-in skeleton's (21, 3) joints, MANO order with tips, without translation.

    ``model``'s forward pass for one hand, the same numbers without torch's cost per call.

    Args:
        model: the float64 built-in skeleton.
        betas: (10,) shape.
        local: (21, 3, 3) local rotations, MANO order with tips (the wrist's orientation first;
            the tips' turn nothing).

    """
    log_scale = np.tensordot(betas, model.shape_log_scales.cpu().numpy(), axes=1)
    offsets = model.rest_offsets.cpu().numpy() * np.exp(log_scale)
    rotations, positions = local.copy(), offsets.copy()  # the wrist's are final already
    for joints, parents in _LEVELS:
        positions[joints] = positions[parents] + np.einsum('kij,kj->ki', rotations[parents],
                                                           offsets[joints])
        rotations[joints] = rotations[parents] @ local[joints]
    return positions


def model_joints(model: HandModel, params: ManoParams) -> np.ndarray:
    """Return the model's (21, 3) joints for one frame's ``params`` (float64, OpenPose order).

    The float64 built-in skeleton is posed in numpy; any other model is called.
    """
    if _posed_in_numpy(model):
        local = axis_angle_to_matrix(np.concatenate([params.global_orient[None], params.hand_pose,
                                                     _TIP_ROTATIONS]))
        joints = _skeleton_joints(model, params.betas, local)
        return joints[model.to_openpose.cpu().numpy()] + params.transl
    reference = next(model.buffers())

    def batch(value: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(value[None], dtype=reference.dtype, device=reference.device)

    with torch.inference_mode():
        out = model(batch(params.global_orient), batch(params.hand_pose), batch(params.betas),
                    batch(params.transl))
    return out.joints[0].cpu().numpy().astype(np.float64)


def rest_joints(model: HandModel, betas: np.ndarray | None = None) -> np.ndarray:
    """Return the model's (21, 3) joints at zero pose and translation, MANO order with tips."""
    shape = np.zeros(NUM_BETAS) if betas is None else np.asarray(betas, dtype=np.float64)
    if _posed_in_numpy(model):
        return _skeleton_joints(model, shape, _REST_ROTATIONS)
    zero = np.zeros(3)
    rest = ManoParams(zero, np.zeros((NUM_HAND_POSE_JOINTS, 3)), shape, zero)
    return model_joints(model, rest)[list(OPENPOSE_TO_MANO)]


def inverse_kinematics(model: HandModel, keypoints: np.ndarray,
                       betas: np.ndarray | None = None,
                       rest: np.ndarray | None = None) -> ManoParams:
    """Return MANO parameters whose joints follow one frame's keypoints, without iterating.

    The wrist orientation is the rigid fit of the rest palm (wrist and MCPs); each finger
    joint then takes the smallest rotation that turns its rest bone onto the keypoints' bone
    (no twist about the bone). Bone lengths stay the model's for ``betas``; the wrist lands on
    the keypoints' wrist (MANO rotates about its rest wrist joint).

    Args:
        model: hand model of the keypoints' side.
        keypoints: (21, 3) joints in metres, OpenPose order, all finite.
        betas: (10,) shape to use (default: the mean shape).
        rest: ``rest_joints(model, betas)`` when the caller keeps it (saves a model call).

    Raises:
        InputError: for keypoints of the wrong shape or with non-finite values.

    """
    points_np, valid = _check_inputs(np.asarray(keypoints)[None], None)
    if not valid.all():
        raise InputError('inverse_kinematics: every keypoint must be finite')
    target = points_np[0][list(OPENPOSE_TO_MANO)]
    rest = rest_joints(model, betas) if rest is None else rest
    rotations = np.zeros((len(PARENTS_WITH_TIPS), 3, 3))
    rotations[0] = _kabsch(rest[_PALM_MANO], target[_PALM_MANO])
    local = np.zeros((NUM_HAND_POSE_JOINTS + 1, 3, 3))
    local[0] = rotations[0]
    rest_bones = rest[_BONE_ENDS] - rest[_BONE_STARTS]
    target_bones = target[_BONE_ENDS] - target[_BONE_STARTS]
    for (joints, parents), rest_bone, target_bone in zip(_LEVELS[:-1], rest_bones, target_bones):
        parent = rotations[parents]
        turned = _swing(np.einsum('kij,kj->ki', parent, rest_bone), target_bone) @ parent
        rotations[joints] = turned
        local[joints] = np.swapaxes(parent, -1, -2) @ turned
    # Products of rotations, orthonormal to rounding: scipy need not orthonormalise them again.
    vectors = Rotation.from_matrix(local, assume_valid=True).as_rotvec()
    shape = np.zeros(NUM_BETAS) if betas is None else np.asarray(betas, dtype=np.float64)
    return ManoParams(vectors[0], vectors[1:], shape.copy(), target[0] - rest[0])
