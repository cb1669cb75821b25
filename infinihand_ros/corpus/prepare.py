"""Complete a corpus sequence: MANO where only joints exist, masks, boxes, 2D and world joints.

Paper Sec. 3.1: MANO is fitted to the 3D keypoints where a dataset has no MANO, per-hand masks
are rendered from the hand surfaces and tight boxes taken from them, and sequences with camera
trajectories get their hands in the shared world frame. The result holds the annotation arrays
of the sample format (``corpus/sample_format.py``) plus ``joint_valid`` (T, 2, 21) and
``mano_fit_error_mm`` (T, 2) (NaN where MANO came from the dataset) and ``hand_confidence``
(T, 2) (the label's confidence: 1 for annotated hands, the detection score for pseudo-labels).
"""

from dataclasses import dataclass

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.corpus.hand_masks import capsule_masks
from infinihand_ros.corpus.hand_masks import masks_to_boxes
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.capsules import joint_radii
from infinihand_ros.mano.fit import fit_mano
from infinihand_ros.mano.fit import ManoFitConfig
import numpy as np
import torch

_MANO_SHAPES = {'global_orient': (3,), 'hand_pose': (NUM_HAND_POSE_JOINTS, 3),
                'betas': (NUM_BETAS,), 'transl': (3,)}


@dataclass(frozen=True)
class PreparedSequence:
    """A sequence ready to write: annotation arrays and (H, W) uint8 hand labels per frame."""

    sequence: CorpusSequence
    annotations: dict[str, np.ndarray]
    labels: list[np.ndarray]


def _fit_missing_mano(sequence: CorpusSequence, models: tuple[HandModel, HandModel],
                      config: ManoFitConfig) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """MANO arrays (T, 2, ...) fitted to the joints, and the fit's frame errors (T, 2) in mm."""
    frames = sequence.num_frames
    mano = {name: np.zeros((frames, 2, *shape)) for name, shape in _MANO_SHAPES.items()}
    errors = np.full((frames, 2), np.nan)
    for side in SIDES:
        valid = sequence.joint_valid[:, side] & sequence.hand_present[:, side, None]
        if not valid.any():
            continue
        result = fit_mano(models[side], sequence.joints_cam[:, side], valid, config)
        for name in _MANO_SHAPES:
            mano[name][:, side] = getattr(result, name)
        errors[:, side] = np.where(sequence.hand_present[:, side], result.frame_errors_mm,
                                   np.nan)
    return mano, errors


def _pose(model: HandModel, mano: dict[str, np.ndarray], side: int) -> tuple[np.ndarray, ...]:
    """Model joints (T, 21, 3) of one side, and its rest root joints (T, 3)."""
    reference = next(model.buffers())
    args = [torch.as_tensor(mano[name][:, side], dtype=reference.dtype) for name in _MANO_SHAPES]
    with torch.no_grad():
        joints = model(*args).joints
        zeros = [torch.zeros_like(args[0]), torch.zeros_like(args[1]), args[2],
                 torch.zeros_like(args[3])]
        root = model(*zeros).joints[:, 0]
    return joints.double().numpy(), root.double().numpy()


def _world(sequence: CorpusSequence, out: dict[str, np.ndarray], roots: np.ndarray) -> None:
    """Add world-frame joints and MANO (NaN without a camera trajectory)."""
    frames = sequence.num_frames
    if sequence.T_world_cam is None:
        out['T_world_cam'] = np.full((frames, 4, 4), np.nan)
        out['joints_world'] = np.full_like(out['joints_cam'], np.nan)
        for name in _MANO_SHAPES:
            out[f'mano_world_{name}'] = np.full_like(out[f'mano_cam_{name}'], np.nan)
        return
    pose = np.asarray(sequence.T_world_cam, np.float64)
    out['T_world_cam'] = pose
    out['joints_world'] = np.einsum('tij,tsnj->tsni', pose[:, :3, :3], out['joints_cam']) \
        + pose[:, None, None, :3, 3]
    for name in _MANO_SHAPES:
        out[f'mano_world_{name}'] = out[f'mano_cam_{name}'].copy()
    for index in range(frames):
        for side in SIDES:
            params = ManoParams(*(out[f'mano_cam_{name}'][index, side] for name in _MANO_SHAPES))
            world = transform_mano_params(params, pose[index, :3, :3], pose[index, :3, 3],
                                          roots[index, side])
            out['mano_world_global_orient'][index, side] = world.global_orient
            out['mano_world_transl'][index, side] = world.transl


def complete_sequence(sequence: CorpusSequence, models: tuple[HandModel, HandModel],
                      fit_config: ManoFitConfig, min_visible_px: int) -> PreparedSequence:
    """Fill in everything the sample format needs.

    Args:
        sequence: the adapter's sequence.
        models: hand models (left, right) the MANO parameters belong to.
        fit_config: settings of the MANO fit (used only when the sequence has no MANO).
        min_visible_px: fewer mask pixels mark a hand not visible.

    """
    frames = sequence.num_frames
    if sequence.mano_cam is None:
        mano, fit_errors = _fit_missing_mano(sequence, models, fit_config)
    else:
        mano = {name: np.asarray(sequence.mano_cam[name], np.float64) for name in _MANO_SHAPES}
        fit_errors = np.full((frames, 2), np.nan)
    posed = [_pose(models[side], mano, side) for side in SIDES]
    model_joints = np.stack([joints for joints, _ in posed], axis=1)
    roots = np.stack([root for _, root in posed], axis=1)
    present = np.asarray(sequence.hand_present, bool)
    valid = np.asarray(sequence.joint_valid, bool) & present[..., None]
    joints_cam = np.where(valid[..., None], sequence.joints_cam, model_joints)
    joints_cam = np.where(present[..., None, None], joints_cam, 0.0)
    width, height = sequence.image_size

    def labels(index: int) -> np.ndarray:
        if sequence.read_labels is not None:
            return sequence.read_labels(index)
        radii = np.stack([joint_radii(mano['betas'][index, side]) for side in SIDES])
        masks = capsule_masks(model_joints[index], radii, present[index], sequence.K[index],
                              width, height)
        out = np.zeros((height, width), np.uint8)
        for side in SIDES:
            out[masks[side]] = fmt.SIDE_LABELS[side]
        return out

    boxes = np.zeros((frames, 2, 4))
    visible = np.zeros((frames, 2), bool)
    label_images = [labels(index) for index in range(frames)]
    for index, image in enumerate(label_images):
        masks = np.stack([image == label for label in fmt.SIDE_LABELS])
        visible[index] = present[index] & (masks.sum(axis=(1, 2)) >= min_visible_px)
        boxes[index] = np.where(visible[index, :, None], masks_to_boxes(masks), 0.0)
    out = {'timestamp_ns': np.asarray(sequence.timestamp_ns, np.int64),
           'K': np.asarray(sequence.K, np.float64), 'hand_present': present,
           'visible': visible, 'joints_cam': joints_cam, 'joint_valid': valid,
           'joints_2d': geometry.project_points(joints_cam, sequence.K[:, None, None]),
           'box_xyxy': boxes, 'mano_fit_error_mm': fit_errors,
           'hand_confidence': present.astype(np.float64) if sequence.hand_confidence is None
           else np.asarray(sequence.hand_confidence, np.float64)}
    for name in _MANO_SHAPES:
        out[f'mano_cam_{name}'] = np.where(
            present.reshape(frames, 2, *([1] * len(_MANO_SHAPES[name]))), mano[name], 0.0)
    _world(sequence, out, roots)
    return PreparedSequence(sequence, out, label_images)
