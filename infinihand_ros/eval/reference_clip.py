"""Real clips with independent references (``shared/data/real_ego``), and scores against them.

A clip folder holds ``frames/NNNNNN.jpg``, ``frames_meta.json`` (each file's time),
``sfm_poses.json``: a pycolmap SfM camera-to-world trajectory (OpenCV axes, arbitrary scale and
gauge) with its lens (COLMAP pixel convention), and ``mediapipe.npz``: MediaPipe Hands alone on
every frame. No ground truth exists for real clips: camera scores compare with the SfM
trajectory after a Sim(3) alignment (ATE as a share of its path) or need no alignment (relative
rotations); hand scores compare the hands written with MediaPipe's.
"""

from collections.abc import Iterator
from dataclasses import dataclass
import json
from pathlib import Path

import cv2
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import invert_transform
from infinihand_ros.core.geometry import rotation_angle_deg
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.hands.side import arm_entry
from infinihand_ros.eval.trajectory import trajectory_metrics
import numpy as np

#: Stamp of a clip's first frame (ns): 2026-01-01T00:00:00Z, as the project's sample data.
FIRST_STAMP_NS = 1_767_225_600 * NS_PER_S


@dataclass(frozen=True)
class ReferenceClip:
    """One real clip and its SfM reference.

    Attributes:
        name: the folder's name.
        files: (N,) frame image paths, in time order.
        timestamps_ns: (N,) their stamps.
        T_world_cam: (N, 4, 4) the SfM camera-to-world poses.
        intrinsics: the SfM lens as a pinhole (OpenCV pixel convention); None for a
            reference without a lens (synthetic ground truth).
        k1: the SfM lens's radial coefficient (SIMPLE_RADIAL).
        path_length: the SfM trajectory's path length (its units).

    """

    name: str
    files: tuple[Path, ...]
    timestamps_ns: np.ndarray
    T_world_cam: np.ndarray
    intrinsics: Intrinsics | None
    k1: float
    path_length: float

    def frames(self) -> Iterator[tuple[np.ndarray, int]]:
        """Yield (RGB uint8 image, stamp) per frame, in order."""
        for file, stamp in zip(self.files, self.timestamps_ns):
            image = cv2.imread(str(file))
            if image is None:
                raise InputError(f'{file}: not a readable image')
            yield cv2.cvtColor(image, cv2.COLOR_BGR2RGB), int(stamp)


def load_reference_clip(folder: str | Path) -> ReferenceClip:
    """Read a clip folder (see the module docstring).

    Raises:
        InputError: for a missing file or a frame without a reference pose.

    """
    folder = Path(folder)
    try:
        meta = json.loads((folder / 'frames_meta.json').read_text(encoding='utf-8'))
        sfm = json.loads((folder / 'sfm_poses.json').read_text(encoding='utf-8'))
    except (OSError, ValueError) as exc:
        raise InputError(f'{folder}: not a reference clip ({exc})') from exc
    names = [frame['file'] for frame in meta['frames']]
    missing = [name for name in names if name not in sfm['poses_c2w']]
    if missing:
        raise InputError(f'{folder}: no reference pose for {missing[:3]}')
    lens = sfm['intrinsics']
    width, height = sfm['image_wh']
    return ReferenceClip(
        name=folder.name, files=tuple(folder / 'frames' / name for name in names),
        timestamps_ns=FIRST_STAMP_NS + np.round(
            np.array([frame['t_sec'] for frame in meta['frames']]) * NS_PER_S).astype(np.int64),
        T_world_cam=np.array([sfm['poses_c2w'][name] for name in names], dtype=np.float64),
        intrinsics=Intrinsics(lens['fx'], lens['fy'], lens['cx'] - 0.5, lens['cy'] - 0.5,
                              width, height),
        k1=float(lens['k1_simple_radial']), path_length=float(
            sfm['trajectory_stats']['path_length']))


def reference_scores(T_world_cam: np.ndarray, clip: ReferenceClip,
                     frames: np.ndarray | None = None) -> dict[str, float]:
    """Score camera-to-world poses (N, 4, 4) against the clip's reference.

    Args:
        T_world_cam: predicted poses of ``frames`` (all frames when None).
        clip: the reference.
        frames: (N,) indices of the clip frames the poses belong to.

    Returns:
        ``ate_pct``: Sim(3)-aligned ATE as a share of the reference's path (%);
        ``rre_median_deg`` / ``rre_mean_deg``: error of the relative rotation between
        consecutive given frames; ``end_deg``: error of the first-to-last relative rotation.

    """
    truth = clip.T_world_cam if frames is None else clip.T_world_cam[frames]
    ate = trajectory_metrics(T_world_cam, truth).ate_m
    pred_rel = invert_transform(T_world_cam[:-1]) @ T_world_cam[1:]
    true_rel = invert_transform(truth[:-1]) @ truth[1:]
    step = rotation_angle_deg(pred_rel[:, :3, :3], true_rel[:, :3, :3])
    end_pred = invert_transform(T_world_cam[0]) @ T_world_cam[-1]
    end_true = invert_transform(truth[0]) @ truth[-1]
    return {'ate_pct': 100.0 * ate / clip.path_length,
            'rre_median_deg': float(np.median(step)), 'rre_mean_deg': float(np.mean(step)),
            'end_deg': float(rotation_angle_deg(end_pred[:3, :3], end_true[:3, :3]))}


#: MediaPipe's unmirrored handedness labels as our sides.
MEDIAPIPE_SIDES = {'Left': LEFT, 'Right': RIGHT}
#: The arm's side of entry decides a reference hand's side from this evidence (``arm_scores``).
ARM_DECIDES = 0.5


def mediapipe_labelled(folder: str | Path) -> list[list[tuple[int, np.ndarray]]]:
    """Return per frame MediaPipe alone's hands as (side, landmarks (21, 2) px), as it labelled.

    Unlike ``mediapipe_hands`` it keeps both hands of a frame where MediaPipe gave them one label.
    """
    data = np.load(Path(folder) / 'mediapipe.npz')
    return [[(MEDIAPIPE_SIDES[str(side)], landmarks[k]) for k, side in enumerate(sides[:count])]
            for landmarks, sides, count in zip(data['landmarks_px'],
                                               data['handedness_unmirrored'], data['num_hands'])]


def mediapipe_hands(folder: str | Path) -> list[dict[int, np.ndarray]]:
    """Return per frame MediaPipe alone's landmarks (21, 2) px by side, from ``mediapipe.npz``.

    Of two hands labelled alike the second is kept (``arm_scores`` counts such frames).
    """
    return [dict(hands) for hands in mediapipe_labelled(folder)]


def arm_scores(results: list[FrameResult], labelled: list[list[tuple[int, np.ndarray]]],
               min_evidence: float = ARM_DECIDES) -> dict[str, int]:
    """Check MediaPipe alone's labels, and ours, against the arm's side of entry.

    On a head-mounted view the wearer's arm enters from its own side (``side.arm_entry``).

    Args:
        results: our results, one per frame.
        labelled: MediaPipe alone's hands per frame (``mediapipe_labelled``).
        min_evidence: the arm decides a hand's side where its evidence is at least this.

    Returns:
        ``arm_decided``: MediaPipe's hands whose arm decides a side; ``reference_with_arm``:
        of them, those MediaPipe labelled that side; ``ours_with_arm``: those with a hand of
        ours on that side; ``reference_label_twice``: frames where MediaPipe gave two hands one
        label (scored as one hand).

    """
    decided = reference = ours = twice = 0
    for result, hands in zip(results, labelled, strict=True):
        twice += len({side for side, _ in hands}) < len(hands)
        width, height = result.intrinsics.width, result.intrinsics.height
        sides = {hand.side for hand in result.hands}
        for side, landmarks in hands:
            evidence = arm_entry(landmarks, width, height)
            if abs(evidence) < min_evidence:
                continue
            arm_side = RIGHT if evidence > 0 else LEFT
            decided += 1
            reference += side == arm_side
            ours += arm_side in sides
    return {'arm_decided': decided, 'reference_with_arm': reference, 'ours_with_arm': ours,
            'reference_label_twice': twice}


def hand_scores(results: list[FrameResult], reference: list[dict[int, np.ndarray]]
                ) -> dict[str, float]:
    """Score the hands of ``results`` (one per frame) against MediaPipe alone's.

    Returns:
        ``mediapipe_hands``: MediaPipe's hands; ``found_same_side`` / ``found_either_side``:
        the share of them with a hand of ours on the same side / on any side;
        ``not_in_mediapipe``: our hands on a side where MediaPipe has none;
        ``reprojection_median`` / ``reprojection_p90``: over hands found on the same side, our
        world joints projected through our camera pose and intrinsics, their median distance
        to MediaPipe's landmarks over the larger side of MediaPipe's landmark box.

    """
    wanted = same = either = extra = 0
    errors = []
    for result, theirs in zip(results, reference, strict=True):
        ours = {hand.side: hand for hand in result.hands}
        wanted += len(theirs)
        same += sum(side in ours for side in theirs)
        either += min(len(ours), len(theirs))
        extra += sum(side not in theirs for side in ours)
        K = result.intrinsics.matrix()
        T_cam_world = invert_transform(result.camera_pose.matrix())
        for side, landmarks in theirs.items():
            if side not in ours or ours[side].joints_world is None:
                continue
            camera = ours[side].joints_world @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
            projected = camera @ K.T
            pixels = projected[:, :2] / projected[:, 2:3]
            size = float(np.max(landmarks.max(axis=0) - landmarks.min(axis=0)))
            errors.append(float(np.median(np.linalg.norm(pixels - landmarks, axis=1))) / size)
    return {'mediapipe_hands': wanted, 'found_same_side': same / max(wanted, 1),
            'found_either_side': either / max(wanted, 1), 'not_in_mediapipe': extra,
            'reprojection_median': float(np.median(errors)) if errors else float('nan'),
            'reprojection_p90': float(np.percentile(errors, 90)) if errors else float('nan')}
