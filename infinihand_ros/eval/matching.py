"""Prediction-target association of the paper's appendix A (shared by every metric).

A frame holds target hands and predicted hands, each with a side, 21 camera-frame joints (metres,
OpenCV optical frame, OpenPose order), a global rotation and an ``xyxy`` pixel box (the paper uses
the box of the projected MANO mesh; ``box_from_projection`` computes one from projected joints or
vertices). Matching follows the paper:

- predictions whose presence score is known must have ``score > 0.5``; a score of ``None`` is an
  unconditional tracker output and counts as positive; rejected predictions take no further part;
- each target box is enlarged about its centre, its width and height each scaled by 1.1 (+10 %);
- candidate pairs have the same side and ``IoU(enlarged target, prediction) > 0.1``; they are taken
  greedily in descending IoU order, one-to-one (ties: lower target, then lower prediction index);
- a target is off-screen when none of its 21 joints projects inside the image
  (``0 <= u < W``, ``0 <= v < H``) with depth above 0.01 m. Off-screen targets and the predictions
  matched to them are excluded from every count. Unmatched predictions are always false positives,
  also in a frame whose targets are all off-screen (or that has no target): they count in the
  pooled FP of F1, while such a frame has no on-screen target and is outside the frame set of FAcc.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import MIN_PROJECTION_DEPTH_M
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.validation import as_array
import numpy as np

#: Matching needs IoU strictly above this value (paper: IoU > 0.1).
IOU_THRESHOLD: Final = 0.1
#: Target boxes are enlarged by 10 %: width and height each multiplied by this factor.
TARGET_BOX_SCALE: Final = 1.1
#: A prediction with a presence score is kept only when the score is strictly above this value.
PRESENCE_THRESHOLD: Final = 0.5
#: Size of an ``xyxy`` box.
BOX_SIZE: Final = 4


def _check_side(side: object, name: str) -> int:
    if isinstance(side, (bool, np.bool_)) or not isinstance(side, (int, np.integer)) \
            or int(side) not in SIDES:
        raise InputError(f'{name}: expected a side in {SIDES} (0 left, 1 right), got {side!r}')
    return int(side)


def _check_box(box: object, name: str) -> np.ndarray:
    array = as_array(box, name, (BOX_SIZE,))
    if array[2] < array[0] or array[3] < array[1]:
        raise InputError(f'{name}: expected an xyxy box with x2 >= x1 and y2 >= y1, '
                         f'got {array.tolist()}')
    return array


@dataclass(frozen=True)
class HandTarget:
    """A ground-truth hand of one frame.

    Attributes:
        side: 0 left, 1 right.
        joints_cam: (21, 3) joints in the camera frame, metres, OpenPose order.
        rotation: (3, 3) global hand rotation in the camera frame.
        box: (4,) ``xyxy`` pixel box (the projected MANO mesh box in the paper).

    """

    side: int
    joints_cam: np.ndarray
    rotation: np.ndarray
    box: np.ndarray

    def __post_init__(self) -> None:
        """Check and convert the fields (raises InputError naming the field)."""
        object.__setattr__(self, 'side', _check_side(self.side, 'HandTarget.side'))
        object.__setattr__(self, 'joints_cam', as_array(
            self.joints_cam, 'HandTarget.joints_cam', (NUM_JOINTS, 3)))
        object.__setattr__(self, 'rotation', as_array(
            self.rotation, 'HandTarget.rotation', (3, 3)))
        object.__setattr__(self, 'box', _check_box(self.box, 'HandTarget.box'))


@dataclass(frozen=True)
class HandPrediction:
    """A predicted hand of one frame (same fields as ``HandTarget`` plus a presence score).

    Attributes:
        side: 0 left, 1 right.
        joints_cam: (21, 3) joints in the camera frame, metres, OpenPose order.
        rotation: (3, 3) global hand rotation in the camera frame.
        box: (4,) ``xyxy`` pixel box.
        score: presence score in [0, 1], or None for an unconditional tracker output (positive).

    """

    side: int
    joints_cam: np.ndarray
    rotation: np.ndarray
    box: np.ndarray
    score: float | None = None

    def __post_init__(self) -> None:
        """Check and convert the fields (raises InputError naming the field)."""
        object.__setattr__(self, 'side', _check_side(self.side, 'HandPrediction.side'))
        object.__setattr__(self, 'joints_cam', as_array(
            self.joints_cam, 'HandPrediction.joints_cam', (NUM_JOINTS, 3)))
        object.__setattr__(self, 'rotation', as_array(
            self.rotation, 'HandPrediction.rotation', (3, 3)))
        object.__setattr__(self, 'box', _check_box(self.box, 'HandPrediction.box'))
        if self.score is not None:
            object.__setattr__(self, 'score', float(as_array(
                self.score, 'HandPrediction.score', ())))

    @property
    def is_positive(self) -> bool:
        """Whether the prediction takes part in matching (score > 0.5 or no score)."""
        return self.score is None or self.score > PRESENCE_THRESHOLD


@dataclass(frozen=True)
class EvalFrame:
    """One evaluated frame: camera, image size, target hands and predicted hands.

    Attributes:
        intrinsics: (3, 3) pinhole K in pixels.
        width: image width in pixels (> 0).
        height: image height in pixels (> 0).
        targets: ground-truth hands (any number, any sides).
        predictions: predicted hands (any number, any sides).

    """

    intrinsics: np.ndarray
    width: int
    height: int
    targets: Sequence[HandTarget] = ()
    predictions: Sequence[HandPrediction] = ()

    def __post_init__(self) -> None:
        """Check and convert the fields (raises InputError naming the field)."""
        object.__setattr__(self, 'intrinsics', as_array(
            self.intrinsics, 'EvalFrame.intrinsics', (3, 3)))
        for name in ('width', 'height'):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value <= 0:
                raise InputError(f'EvalFrame.{name}: expected a positive pixel count, '
                                 f'got {value!r}')
        for name, kind in (('targets', HandTarget), ('predictions', HandPrediction)):
            items = tuple(getattr(self, name))
            for index, item in enumerate(items):
                if not isinstance(item, kind):
                    raise InputError(f'EvalFrame.{name}[{index}]: expected a {kind.__name__}, '
                                     f'got {type(item).__name__}')
            object.__setattr__(self, name, items)

    @property
    def diagonal_px(self) -> float:
        """Image diagonal ``D = sqrt(W^2 + H^2)`` in pixels."""
        return float(np.hypot(self.width, self.height))


@dataclass(frozen=True)
class FrameMatch:
    """Result of matching one frame; indices refer to ``EvalFrame.targets`` / ``.predictions``.

    Attributes:
        matched: (target, prediction) pairs with an on-screen target (true positives).
        missed: on-screen targets left unmatched (false negatives).
        false_positives: kept predictions left unmatched.
        off_screen_targets: targets with no joint inside the image (excluded).
        excluded_predictions: predictions matched to an off-screen target (excluded).
        rejected_predictions: predictions whose score is not above 0.5 (not matched).
        on_screen_joints: (num_targets, 21) bool, target joints inside the image at depth > 0.01 m.

    """

    matched: tuple[tuple[int, int], ...]
    missed: tuple[int, ...]
    false_positives: tuple[int, ...]
    off_screen_targets: tuple[int, ...]
    excluded_predictions: tuple[int, ...]
    rejected_predictions: tuple[int, ...]
    on_screen_joints: np.ndarray = field(repr=False)

    @property
    def has_on_screen_target(self) -> bool:
        """Whether the frame belongs to the FAcc frame set (some target left after exclusion)."""
        return bool(self.matched or self.missed)

    @property
    def is_correct(self) -> bool:
        """Whether the frame has no false positive and no false negative."""
        return not self.false_positives and not self.missed


def enlarge_boxes(boxes: np.ndarray, scale: float = TARGET_BOX_SCALE) -> np.ndarray:
    """Scale ``xyxy`` boxes (..., 4) about their centres: width and height each times ``scale``."""
    b = np.asarray(boxes, dtype=np.float64)
    centre = (b[..., :2] + b[..., 2:]) / 2.0
    half = (b[..., 2:] - b[..., :2]) * (scale / 2.0)
    return np.concatenate([centre - half, centre + half], axis=-1)


def box_iou(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Intersection over union of every pair of ``xyxy`` boxes: (N, 4) x (M, 4) -> (N, M).

    A pair whose union has zero area has IoU 0.
    """
    a = np.asarray(boxes_a, dtype=np.float64).reshape(-1, BOX_SIZE)[:, None, :]
    b = np.asarray(boxes_b, dtype=np.float64).reshape(-1, BOX_SIZE)[None, :, :]
    low = np.maximum(a[..., :2], b[..., :2])
    high = np.minimum(a[..., 2:], b[..., 2:])
    inter = np.prod(np.clip(high - low, 0.0, None), axis=-1)
    area_a = np.prod(a[..., 2:] - a[..., :2], axis=-1)
    area_b = np.prod(b[..., 2:] - b[..., :2], axis=-1)
    union = area_a + area_b - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0.0)


def box_from_points(points_px: np.ndarray) -> np.ndarray:
    """Tight ``xyxy`` box (..., 4) of pixel points (..., P, 2)."""
    p = np.asarray(points_px, dtype=np.float64)
    return np.concatenate([p.min(axis=-2), p.max(axis=-2)], axis=-1)


def box_from_projection(points_cam: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """Box (..., 4) of camera-frame points (..., P, 3) (joints or mesh vertices) projected with K.

    Depth is floored at 0.01 m as in ``core.geometry.project_points``; the box is not clipped to
    the image.
    """
    return box_from_points(project_points(points_cam, intrinsics))


def on_screen_joints(joints_cam: np.ndarray, intrinsics: np.ndarray, width: int,
                     height: int) -> np.ndarray:
    """Which joints (..., J, 3) project inside the image with depth above 0.01 m -> bool (..., J).

    Inside means ``0 <= u < width`` and ``0 <= v < height`` in pixel coordinates of K.
    """
    joints = np.asarray(joints_cam, dtype=np.float64)
    uv = project_points(joints, intrinsics)
    inside_u = (uv[..., 0] >= 0.0) & (uv[..., 0] < width)
    inside_v = (uv[..., 1] >= 0.0) & (uv[..., 1] < height)
    return inside_u & inside_v & (joints[..., 2] > MIN_PROJECTION_DEPTH_M)


def greedy_match(iou: np.ndarray, allowed: np.ndarray,
                 threshold: float = IOU_THRESHOLD) -> list[tuple[int, int]]:
    """One-to-one greedy matching in descending IoU order.

    Args:
        iou: (N, M) IoU of target n with prediction m.
        allowed: (N, M) bool, pairs that may match (same side, kept prediction).
        threshold: a pair needs IoU strictly above it.

    Returns:
        (target, prediction) pairs in the order they were taken; ties go to the lower target,
        then the lower prediction index.

    """
    scores = np.asarray(iou, dtype=np.float64)
    rows, cols = np.nonzero(np.asarray(allowed, dtype=bool) & (scores > threshold))
    order = np.lexsort((cols, rows, -scores[rows, cols]))
    used_rows: set[int] = set()
    used_cols: set[int] = set()
    pairs = []
    for row, col in zip(rows[order].tolist(), cols[order].tolist()):
        if row not in used_rows and col not in used_cols:
            used_rows.add(row)
            used_cols.add(col)
            pairs.append((row, col))
    return pairs


def match_frame(frame: EvalFrame) -> FrameMatch:
    """Match one frame's predictions to its targets and apply the off-screen exclusion."""
    targets, predictions = frame.targets, frame.predictions
    if targets:
        on_screen = on_screen_joints(np.stack([t.joints_cam for t in targets]), frame.intrinsics,
                                     frame.width, frame.height)
    else:
        on_screen = np.zeros((0, NUM_JOINTS), dtype=bool)
    kept = np.array([p.is_positive for p in predictions], dtype=bool)
    pairs: list[tuple[int, int]] = []
    if targets and predictions:
        iou = box_iou(enlarge_boxes(np.stack([t.box for t in targets])),
                      np.stack([p.box for p in predictions]))
        same_side = (np.array([t.side for t in targets])[:, None]
                     == np.array([p.side for p in predictions])[None, :])
        pairs = greedy_match(iou, same_side & kept[None, :])
    visible = on_screen.any(axis=1)
    matched_targets = {t for t, _ in pairs}
    matched_predictions = {p for _, p in pairs}
    return FrameMatch(
        matched=tuple(sorted((t, p) for t, p in pairs if visible[t])),
        missed=tuple(t for t in range(len(targets)) if visible[t] and t not in matched_targets),
        false_positives=tuple(p for p in range(len(predictions))
                              if kept[p] and p not in matched_predictions),
        off_screen_targets=tuple(int(t) for t in np.flatnonzero(~visible)),
        excluded_predictions=tuple(sorted(p for t, p in pairs if not visible[t])),
        rejected_predictions=tuple(int(p) for p in np.flatnonzero(~kept)),
        on_screen_joints=on_screen,
    )
