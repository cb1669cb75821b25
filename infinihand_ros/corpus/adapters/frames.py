"""Shared pieces of the dataset adapters: frame loaders, frame changes and empty tracks.

Frame changes are written once here so every adapter states its dataset's convention by name:
``GL_TO_CV`` turns an OpenGL / ARKit camera frame (x right, y up, z toward the viewer) into
ours (OpenCV optical: x right, y down, z forward).
"""

from collections.abc import Sequence
from pathlib import Path
from typing import Final

import av
import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.corpus.sequence import RgbLoader
import numpy as np

#: Point map from an OpenGL-style camera frame to the OpenCV optical frame (its own inverse).
GL_TO_CV: Final = np.diag([1.0, -1.0, -1.0])


def empty_hands(frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (hand_present (T, 2), joints_cam (T, 2, 21, 3) NaN, joint_valid (T, 2, 21))."""
    return (np.zeros((frames, len(SIDES)), bool),
            np.full((frames, len(SIDES), NUM_JOINTS, 3), np.nan),
            np.zeros((frames, len(SIDES), NUM_JOINTS), bool))


def rebase_to_first(T_world_cam: np.ndarray) -> np.ndarray:
    """Return camera-to-world poses (T, 4, 4) re-expressed with the first camera as world."""
    poses = np.asarray(T_world_cam, np.float64)
    return np.linalg.inv(poses[0]) @ poses


def stamps_from_rate(frames: int, fps: float) -> np.ndarray:
    """Return (T,) int64 stamps of a constant-rate sequence starting at 0."""
    return np.round(np.arange(frames) * NS_PER_S / fps).astype(np.int64)


class ImageFiles:
    """RGB loader over a list of image files (one per frame), optionally undistorted."""

    def __init__(self, paths: Sequence[Path], K: np.ndarray | None = None,
                 distortion: np.ndarray | None = None) -> None:
        """Hold the paths; with ``distortion`` (OpenCV coefficients) frames are undistorted."""
        self._paths = list(paths)
        self._K, self._distortion = K, distortion

    def __call__(self, index: int) -> np.ndarray:
        """Return frame ``index`` as (H, W, 3) uint8 RGB (InputError if unreadable)."""
        image = cv2.imread(str(self._paths[index]), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f'{self._paths[index]}: missing or unreadable image')
        if self._distortion is not None:
            image = cv2.undistort(image, self._K, self._distortion)
        return np.ascontiguousarray(image[:, :, ::-1])


class VideoFrames:
    """RGB loader over a video file, decoding forward (the builder reads frames in order).

    A request for an earlier frame reopens the file; frames are never all held in memory.
    """

    def __init__(self, path: Path, first_frame: int = 0) -> None:
        """Read ``path`` (any FFmpeg video); frame ``i`` is its frame ``first_frame + i``."""
        self._path, self._first = Path(path), first_frame
        self._frames = None
        self._next = 0

    def _open(self) -> None:
        try:
            container = av.open(str(self._path))
        except (av.FFmpegError, OSError) as exc:
            raise InputError(f'video {self._path} cannot be opened ({exc})') from exc
        self._frames = container.decode(video=0)
        self._next = 0

    def __call__(self, index: int) -> np.ndarray:
        """Return frame ``index`` as (H, W, 3) uint8 RGB (InputError past the end)."""
        wanted = self._first + index
        if self._frames is None or wanted < self._next:
            self._open()
        for frame in self._frames:
            self._next += 1
            if self._next - 1 == wanted:
                return frame.to_ndarray(format='rgb24')
        self._frames = None
        raise InputError(f'video {self._path} has no frame {wanted}')


def image_size_of(read_rgb: RgbLoader) -> tuple[int, int]:
    """Return (width, height) of a loader's first frame."""
    rgb = read_rgb(0)
    return int(rgb.shape[1]), int(rgb.shape[0])
