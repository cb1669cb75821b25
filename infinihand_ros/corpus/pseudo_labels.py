"""Pseudo-labels from unlabeled recordings (``build_corpus --from-bags``; paper Sec. 3.1 spirit).

Per frame of a bag, the 2D source (MediaPipe Hands) finds each side's hand: its 21 pixel joints
and its metric landmarks (hand-centred, axes along the image's, OpenCV-like: x right, y down,
z away). ``cv2.solvePnP`` (SQPnP) with the bag's intrinsics places the metric hand in the
camera, giving camera-frame joints; MANO is then fitted to them and masks rendered by the
builder, and cleaning runs as for any dataset. A hand-frame is kept when the detection scores
at least ``min_confidence``, the hand lies in front of the camera and the PnP reprojection error
stays under ``max_reprojection_px``; its confidence is the detection score.

What such labels can teach: the user's camera (intrinsics, distortion-free image statistics,
viewpoint), their hands' appearance, lighting and scenes, and 2D joint positions about as well
as MediaPipe places them. What they cannot: anything MediaPipe gets wrong (occluded fingers,
interacting hands, depth ambiguities), metric depth beyond what MediaPipe's hand-size prior
gives (PnP scale comes from its metric landmarks, not from the user's hand), and camera
trajectories (Stage I only: no camera poses are produced).
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Final

import cv2
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.corpus.adapters.frames import empty_hands
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.engine.hands.keypoints import KeypointSource
import numpy as np

SOURCE: Final = 'pseudo-labels'
LICENCE: Final = "the recording owner's"
_PNG: Final = '.png'


@dataclass(frozen=True)
class PseudoLabelConfig:
    """Pseudo-label settings (``config/corpus.yaml``, section ``pseudo_labels``).

    Attributes:
        min_confidence: detections scoring lower give no label.
        max_reprojection_px: PnP fits with a larger mean reprojection error give no label.

    """

    min_confidence: float = 0.7
    max_reprojection_px: float = 8.0

    def __post_init__(self) -> None:
        require_positive('pseudo_labels', min_confidence=self.min_confidence,
                         max_reprojection_px=self.max_reprojection_px)


def place_hand(detection: Detection2D, K: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Camera-frame joints (21, 3) m of a detection by PnP, and the mean reprojection error.

    Returns None without metric landmarks or when the hand lands behind the camera.
    """
    if detection.joints_metric is None:
        return None
    metric = np.asarray(detection.joints_metric, np.float64)
    pixels = np.asarray(detection.joints_2d, np.float64)
    found, rvec, tvec = cv2.solvePnP(metric, pixels, K, None, flags=cv2.SOLVEPNP_SQPNP)
    if not found:
        return None
    rotation, _ = cv2.Rodrigues(rvec)
    joints = metric @ rotation.T + tvec.reshape(1, 3)
    if np.any(joints[:, 2] <= 0):
        return None
    projected = joints[:, :2] / joints[:, 2:] * K[[0, 1], [0, 1]] + K[:2, 2]
    return joints, float(np.linalg.norm(projected - pixels, axis=1).mean())


class _PngFrames:
    """Frames kept losslessly compressed in memory, decoded on demand."""

    def __init__(self) -> None:
        self._encoded: list[np.ndarray] = []

    def append(self, rgb: np.ndarray) -> None:
        ok, data = cv2.imencode(_PNG, np.ascontiguousarray(rgb[:, :, ::-1]))
        if not ok:
            raise InputError('a frame could not be encoded')
        self._encoded.append(data)

    def __call__(self, index: int) -> np.ndarray:
        bgr = cv2.imdecode(self._encoded[index], cv2.IMREAD_COLOR)
        return np.ascontiguousarray(bgr[:, :, ::-1])


def pseudo_label_bag(bag: Path, source: KeypointSource,
                     config: PseudoLabelConfig) -> CorpusSequence:
    """Label one bag's camera frames with the 2D source.

    Returns:
        The sequence (no MANO, no camera trajectory); ``hand_confidence`` holds each
        hand-frame's detection score (0 where no label was kept).

    Raises:
        InputError: when the bag has no frames or a frame has no intrinsics.

    """
    frames, stamps, Ks, images = [], [], [], _PngFrames()
    for frame in read_camera_frames(bag):
        if frame.intrinsics is None:
            raise InputError(f'{bag}: frame {frame.timestamp_ns} has no CameraInfo; '
                             'pseudo-labels need the intrinsics for PnP')
        intr = frame.intrinsics
        K = np.array([[intr.fx, 0.0, intr.cx], [0.0, intr.fy, intr.cy], [0.0, 0.0, 1.0]])
        frames.append(source.detect(frame.rgb, len(frames)))
        stamps.append(frame.timestamp_ns)
        Ks.append(K)
        images.append(frame.rgb)
        size = (frame.rgb.shape[1], frame.rgb.shape[0])
    if not frames:
        raise InputError(f'{bag}: no camera frames')
    present, joints, valid = empty_hands(len(frames))
    confidence = np.zeros(present.shape)
    for index, detections in enumerate(frames):
        for side in SIDES:
            same = [d for d in detections if d.side == side]
            best = max(same, key=lambda d: d.confidence) if same else None
            if best is None or best.confidence < config.min_confidence:
                continue
            placed = place_hand(best, Ks[index])
            if placed is None or placed[1] > config.max_reprojection_px:
                continue
            joints[index, side], confidence[index, side] = placed[0], best.confidence
            present[index, side] = True
            valid[index, side] = True
    return CorpusSequence(
        sequence_id=Path(bag).name, source=SOURCE, licence=LICENCE, image_size=size,
        timestamp_ns=np.asarray(stamps, np.int64), K=np.stack(Ks), T_world_cam=None,
        hand_present=present, joints_cam=joints, joint_valid=valid, mano_cam=None,
        read_rgb=images, hand_confidence=confidence)
