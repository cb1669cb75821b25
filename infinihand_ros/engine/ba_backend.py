"""The engine's bundle-adjustment seam: one interface for every place BA can run.

The engine builds each keyframe once (``keyframe_input``: source image, metric depth, the
metrically scaled raw pose, the hand boxes and the forearms they continue as a mask) and hands
it to its backend with ``offer``; before each frame is posed it calls ``fold_in`` so finished
BA results reach the pose track as corrections. Backends: ``InProcessBA``
(``engine/ba_in_process.py``, a BA worker process beside the stream) and ``RemoteBA``
(``engine/ba_remote.py``, the bundle-adjustment node: keyframes out, corrections in, through a
transport the caller owns). A new backend is one module that implements these calls.
"""

from typing import Final
from typing import Protocol

import cv2
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.hand_conventions import MIDDLE_MCP
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.pose_track import PoseTrack
import numpy as np

#: Half-angle (deg) by which a forearm's mask opens beyond the hand's axis.
ARM_SPREAD_DEG: Final = 20.0


class BABackend(Protocol):
    """What the engine asks of a bundle-adjustment backend (all calls from the engine's caller)."""

    def offer(self, keyframe: KeyframeInput) -> None:
        """Take a keyframe; never waits for BA."""

    def fold_in(self, track: PoseTrack) -> None:
        """Hand finished BA results to ``track`` as corrections; prune what nobody can query."""

    def settle(self, track: PoseTrack, timeout_s: float | None = None) -> bool:
        """Wait for queued BA work (where the backend can), fold it in; return whether all done."""

    def failed_frames(self) -> frozenset[int]:
        """Return the frames whose last BA call failed (at least those the pose track holds)."""

    def episode_refined(self) -> bool:
        """Return whether ``settle`` refined the whole episode into the track's poses."""

    def statistics(self) -> dict[str, object]:
        """Return the backend's state and counters for diagnostics and reports."""

    def reset(self) -> None:
        """Forget the sequence (a new stream starts)."""

    def close(self) -> None:
        """Stop background work promptly (queued work is dropped: ``settle`` first); idempotent."""


def _box_pixels(hand: HandState) -> tuple[int, int, int, int]:
    """Return the hand box's pixel bounds (x0, y0, x1, y1), x1/y1 exclusive, never inverted."""
    x0, y0 = np.floor(np.clip(hand.box_xyxy[:2], 0, None)).astype(int)
    x1, y1 = np.ceil(hand.box_xyxy[2:]).astype(int)
    return int(x0), int(y0), int(max(x1, x0)), int(max(y1, y0))


def box_mask(hands: tuple[HandState, ...], intrinsics: Intrinsics) -> np.ndarray:
    """Return an (H, W) bool mask covering the hands' boxes."""
    mask = np.zeros((intrinsics.height, intrinsics.width), dtype=bool)
    for hand in hands:
        x0, y0, x1, y1 = _box_pixels(hand)
        mask[y0:y1, x0:x1] = True
    return mask


def moving_mask(hands: tuple[HandState, ...], intrinsics: Intrinsics) -> np.ndarray:
    """Return an (H, W) bool mask of what moves with the hands (kept out of BA's tracks).

    Each hand's box, and its forearm: a wedge from the wrist away from the middle knuckle to
    the image border, as wide as the box's shorter side at the wrist and opening by
    ``ARM_SPREAD_DEG`` on each side (the wrist bends the hand off the forearm's axis).
    """
    mask = box_mask(hands, intrinsics).astype(np.uint8)
    reach = float(np.hypot(intrinsics.width, intrinsics.height))
    for hand in hands:
        x0, y0, x1, y1 = _box_pixels(hand)
        wrist, knuckle = project_points(hand.joints_cam[[WRIST, MIDDLE_MCP]],
                                        intrinsics.matrix())
        along = wrist - knuckle
        length = float(np.linalg.norm(along))
        if not np.isfinite(length) or length < 1e-6:
            continue
        along /= length
        across = np.array([-along[1], along[0]])
        half = 0.5 * min(x1 - x0, y1 - y0)
        spread = half + reach * np.tan(np.radians(ARM_SPREAD_DEG))
        end = wrist + reach * along
        wedge = np.array([wrist + half * across, end + spread * across,
                          end - spread * across, wrist - half * across])
        cv2.fillPoly(mask, [np.round(wedge).astype(np.int32)], 1)
    return mask.astype(bool)


def keyframe_input(frame_index: int, timestamp_ns: int, image: np.ndarray,
                   depth_m: np.ndarray, pose: CameraPose, intrinsics: Intrinsics,
                   hands: tuple[HandState, ...], scale: float = 1.0,
                   calibrated: bool = False) -> KeyframeInput:
    """Return what BA gets of a keyframe (its pose: the raw pose at metric ``scale``).

    ``calibrated``: the intrinsics were given, not predicted (BA then holds the lens). The
    image is the engine's rectified one, so BA gets the pinhole camera with the same K.
    """
    pinhole = intrinsics.pinhole()
    return KeyframeInput(frame_index, timestamp_ns, image, depth_m, pose.matrix(), pinhole,
                         moving_mask(hands, pinhole), scale, calibrated)


def prune_corrections(track: PoseTrack, stamps_still_used: list[int]) -> None:
    """Drop corrections older than every frame in ``track`` and every stamp still used."""
    oldest = track.oldest_timestamp_ns
    if oldest is not None:
        track.corrections.prune(min([oldest, *stamps_still_used]))


class KeyframeFeed:
    """The keyframes a BA backend is offered: with image and depth, ``min_interval_s`` apart."""

    def __init__(self, backend: BABackend, min_interval_s: float) -> None:
        """Offer keyframes to ``backend``, at least ``min_interval_s`` apart by stamp."""
        self.backend = backend
        self._interval_ns = round(1e9 * min_interval_s)
        self._last_ns: int | None = None  # stamp of the last keyframe offered

    def wants(self, frame: PreparedFrame, has_depth: bool) -> bool:
        """Return whether a frame goes to BA: a keyframe with its image and depth, not too soon."""
        return (frame.keyframe and frame.source_image is not None and has_depth
                and (self._last_ns is None
                     or frame.timestamp_ns - self._last_ns >= self._interval_ns))

    def offer(self, record: CameraSpaceFrame, depth_m: np.ndarray, track: PoseTrack,
              calibrated: bool) -> None:
        """Offer a keyframe (its metric depth, the track's scaled pose) to the backend."""
        frame = record.frame
        self._last_ns = frame.timestamp_ns
        self.backend.offer(keyframe_input(frame.index, frame.timestamp_ns, frame.source_image,
                                          depth_m, track.scaled(frame.index), record.intrinsics,
                                          record.hands, track.scale, calibrated))

    def reset(self) -> None:
        """Start a new sequence: no keyframe offered yet."""
        self._last_ns = None
