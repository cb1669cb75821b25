"""One lens per stream: the intrinsics a stream's frames get where the caller gave none.

With hands found outside the model and no given intrinsics, a moving camera holds the median of
the intrinsics the model predicted on its first block (the anchor frames), and the frames after
it are given that lens: a pose is never re-measured through another focal length (a still
camera would seem to move). A fixed camera holds the median over its first ``lens_frames``
frames, after which its frames need no model at all. ``lens_frames`` 0, the paper's hand branch,
or given intrinsics: nothing is held (intrinsics predicted on every frame).
"""

from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import PreparedFrame
import numpy as np
import torch


class StreamLens:
    """The lens held for the current stream (``fixed``), from its first predictions."""

    def __init__(self, lens_frames: int, static: bool, hand_branch: bool) -> None:
        """Hold no lens yet.

        Args:
            lens_frames: the engine's ``lens_frames`` (0: never hold a lens).
            static: a fixed camera (``camera_motion: static``).
            hand_branch: the hands come from the model's hand branch (no lens is held).

        """
        self._wanted = lens_frames
        self._static = static
        self._holds = lens_frames > 0 and not hand_branch
        self._predicted: list[Intrinsics] = []  # a fixed camera's first predicted intrinsics
        self.fixed: Intrinsics | None = None  # ... their median, or a moving camera's, once held

    def reset(self) -> None:
        """Start a new stream: no lens held."""
        self._predicted = []
        self.fixed = None

    def hold(self, frames: list[PreparedFrame], used: torch.Tensor) -> torch.Tensor:
        """Return a moving camera's first block's intrinsics as one lens, held for the stream.

        Args:
            frames: the block's frames.
            used: (1, S, 3, 3) the intrinsics the model used, model-input pixels.

        Returns:
            ``used``, or with a lens to hold, its median for every frame (held in ``fixed`` in
            source pixels, and given to the frames after it). Unchanged with given intrinsics,
            a fixed camera (``collect``), a lens held already, or none to hold.

        """
        if (self.fixed is not None or self._static or not self._holds
                or any(frame.intrinsics is not None for frame in frames)):
            return used
        median = np.median(used[0].double().cpu().numpy(), axis=0)
        height, width = frames[0].pixels.shape[-2:]
        self.fixed = frames[0].mapping.intrinsics_to_source(
            Intrinsics.from_matrix(median, width, height))
        return torch.as_tensor(median, dtype=used.dtype).expand_as(used[0])[None].clone()

    def calibrated(self, frame: PreparedFrame) -> bool:
        """Return whether the frame's intrinsics were given (not the lens held from predictions).

        BA refines a lens only where none was given.
        """
        return frame.intrinsics is not None and frame.intrinsics is not self.fixed

    def collect(self, record: CameraSpaceFrame) -> None:
        """Collect a fixed camera's predicted intrinsics; hold their median once enough came."""
        if (record.frame.intrinsics is not None or self.fixed is not None
                or not self._static or not self._holds):
            return
        self._predicted.append(record.intrinsics)
        if len(self._predicted) == self._wanted:
            values = np.median([[k.fx, k.fy, k.cx, k.cy] for k in self._predicted], axis=0)
            self.fixed = Intrinsics(*values, record.intrinsics.width, record.intrinsics.height)


def given_intrinsics(frames: list[PreparedFrame]
                     ) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """Return (1, S, 3, 3) model-size K of the frames with given intrinsics, and which.

    Returns:
        float64 K per frame (identity where none was given) and a (1, S) bool mask of the
        frames with given intrinsics; (None, None) when none has any.

    """
    known = [frame.intrinsics is not None for frame in frames]
    if not any(known):
        return None, None
    matrices = np.stack([frame.mapping.intrinsics_to_model(frame.intrinsics).matrix()
                         if frame.intrinsics is not None else np.eye(3) for frame in frames])
    return (torch.as_tensor(matrices, dtype=torch.float64)[None],
            torch.tensor(known)[None])
