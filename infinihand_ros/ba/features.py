"""Per-keyframe matching features, computed once per frame and cached across BA calls.

The binary keyframe pool hands a frame to BA twice (selected once, retained, selected again),
and a retained frame may wait in the pool through several calls. What depends on one frame alone
(grey image, trackable-pixel mask, corners, ORB keypoints and descriptors) is computed on its
first selection and kept in a ``FeatureCache`` keyed by frame id (and checked against the stamp)
until the caller says the frame can no longer be selected (``retain``), so the cache never holds
more than the pool.
"""

from collections.abc import Iterable
from dataclasses import dataclass

import cv2
from infinihand_ros.ba.config import TrackingConfig
from infinihand_ros.ba.keyframe import KeyframeInput
import numpy as np


@dataclass(frozen=True)
class KeyframeFeatures:
    """What matching needs from one keyframe.

    Attributes:
        frame_id: the keyframe's id.
        timestamp_ns: its stamp (ns); a cached entry is used only for the same id and stamp.
        gray: (H, W) uint8 grey image.
        valid: (H, W) uint8, 255 where tracking is allowed (no dilated hand, valid depth).
        corners: (C, 2) float64 corners on valid pixels (px), best first, pairwise at least
            ``min_corner_distance_px`` apart.
        orb_xy: (O, 2) float64 ORB keypoint positions (px).
        orb_descriptors: (O, 32) uint8 ORB descriptors, or None without keypoints.

    """

    frame_id: int
    timestamp_ns: int
    gray: np.ndarray
    valid: np.ndarray
    corners: np.ndarray
    orb_xy: np.ndarray
    orb_descriptors: np.ndarray | None


def trackable_mask(keyframe: KeyframeInput, config: TrackingConfig) -> np.ndarray:
    """Return (H, W) uint8, 255 off the dilated hand masks where the depth is in range."""
    hands = keyframe.hand_mask.astype(np.uint8)
    rows = np.flatnonzero(keyframe.hand_mask.any(axis=1))
    cols = np.flatnonzero(keyframe.hand_mask.any(axis=0))
    if config.hand_margin_px > 0 and len(rows):
        # Dilate only the hands' bounding box grown by the margin: same result, less work.
        margin = config.hand_margin_px
        box = (slice(max(rows[0] - margin, 0), rows[-1] + margin + 1),
               slice(max(cols[0] - margin, 0), cols[-1] + margin + 1))
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))
        hands[box] = cv2.dilate(hands[box], kernel)
    depth = keyframe.depth
    good_depth = np.isfinite(depth) & (depth >= config.min_depth_m) & (depth <= config.max_depth_m)
    return ((hands == 0) & good_depth).astype(np.uint8) * 255


def compute_features(keyframe: KeyframeInput, config: TrackingConfig) -> KeyframeFeatures:
    """Return the features of one keyframe (no caching)."""
    gray = cv2.cvtColor(keyframe.image, cv2.COLOR_RGB2GRAY)
    valid = trackable_mask(keyframe, config)
    corners = cv2.goodFeaturesToTrack(gray, config.max_corners, config.corner_quality,
                                      config.min_corner_distance_px, mask=valid)
    corners = np.zeros((0, 2)) if corners is None else corners.reshape(-1, 2).astype(np.float64)
    orb = cv2.ORB_create(nfeatures=config.orb_features)
    keypoints, descriptors = orb.detectAndCompute(gray, valid)
    orb_xy = np.array([keypoint.pt for keypoint in keypoints], dtype=np.float64).reshape(-1, 2)
    return KeyframeFeatures(keyframe.frame_id, keyframe.timestamp_ns, gray, valid, corners,
                            orb_xy, descriptors)


class FeatureCache:
    """Features of the keyframes that may still be selected, keyed by frame id."""

    def __init__(self, config: TrackingConfig) -> None:
        """Start empty; features are computed with ``config``."""
        self.config = config
        self._by_id: dict[int, KeyframeFeatures] = {}
        self.computed = 0

    def __len__(self) -> int:
        """Return the number of cached keyframes."""
        return len(self._by_id)

    def features(self, keyframe: KeyframeInput) -> KeyframeFeatures:
        """Return the keyframe's features, computing (and caching) them on first use.

        An entry with the same id but another stamp (a frame id reused by a new sequence) is
        recomputed, never reused.
        """
        cached = self._by_id.get(keyframe.frame_id)
        if cached is None or cached.timestamp_ns != keyframe.timestamp_ns:
            cached = compute_features(keyframe, self.config)
            self._by_id[keyframe.frame_id] = cached
            self.computed += 1
        return cached

    def retain(self, frame_ids: Iterable[int]) -> None:
        """Keep only the features of ``frame_ids`` (the frames a later call may select)."""
        keep = {int(frame_id) for frame_id in frame_ids}
        self._by_id = {key: value for key, value in self._by_id.items() if key in keep}

    def reset(self) -> None:
        """Drop every cached feature (new sequence)."""
        self._by_id = {}
