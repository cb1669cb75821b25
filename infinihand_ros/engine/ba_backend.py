"""The engine's bundle-adjustment seam: one interface for every place BA can run.

The engine builds each keyframe once (``keyframe_input``: source image, metric depth, the
metrically scaled raw pose, the hand boxes as a mask) and hands it to its backend with
``offer``; before each frame is posed it calls ``fold_in`` so finished BA results reach the
pose track as corrections. Backends: ``InProcessBA`` (``engine/ba_in_process.py``, a BA worker
process beside the stream) and ``RemoteBA`` (``engine/ba_remote.py``, the bundle-adjustment
node: keyframes out, corrections in, through a transport the caller owns). A new backend is one
module that implements these calls.
"""

from typing import Protocol

from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.pose_track import PoseTrack
import numpy as np


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

    def statistics(self) -> dict[str, object]:
        """Return the backend's state and counters for diagnostics and reports."""

    def reset(self) -> None:
        """Forget the sequence (a new stream starts)."""

    def close(self) -> None:
        """Stop background work promptly (queued work is dropped: ``settle`` first); idempotent."""


def hand_mask_from_boxes(hands: tuple[HandState, ...], intrinsics: Intrinsics) -> np.ndarray:
    """Return an (H, W) bool mask covering the hands' boxes (kept out of tracking)."""
    mask = np.zeros((intrinsics.height, intrinsics.width), dtype=bool)
    for hand in hands:
        x0, y0 = np.floor(np.clip(hand.box_xyxy[:2], 0, None)).astype(int)
        x1, y1 = np.ceil(hand.box_xyxy[2:]).astype(int)
        mask[y0:max(y1, y0), x0:max(x1, x0)] = True
    return mask


def keyframe_input(frame_index: int, timestamp_ns: int, image: np.ndarray,
                   depth_m: np.ndarray, pose: CameraPose, intrinsics: Intrinsics,
                   hands: tuple[HandState, ...]) -> KeyframeInput:
    """Return what BA gets of a keyframe (its pose: the metrically scaled raw pose)."""
    return KeyframeInput(frame_index, timestamp_ns, image, depth_m, pose.matrix(), intrinsics,
                         hand_mask_from_boxes(hands, intrinsics))


def prune_corrections(track: PoseTrack, stamps_still_used: list[int]) -> None:
    """Drop corrections older than every frame in ``track`` and every stamp still used."""
    oldest = track.oldest_timestamp_ns
    if oldest is not None:
        track.corrections.prune(min([oldest, *stamps_still_used]))
