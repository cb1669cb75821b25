"""One lens per stream: the intrinsics a stream's frames get where the caller gave none.

With hands found outside the model and no given intrinsics, a moving camera holds the median of
the intrinsics the model predicted on its first block (the anchor frames), and the frames after
it are given that lens: a pose is never re-measured through another focal length (a still
camera would seem to move). A fixed camera's frames need no model at all: its lens is the median
of ``lens_frames`` predictions made beside the stream (``engine/lens_warmup.py``), and its first
frames go out with a provisional one meanwhile. ``lens_frames`` 0, the paper's hand branch, or
given intrinsics: nothing is held (intrinsics predicted on every frame).
"""

from collections.abc import Callable

from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.lens_warmup import LensWarmup
import numpy as np
import torch


class StreamLens:
    """The lens held for the current stream (``fixed``), from its first predictions."""

    def __init__(self, lens_frames: int, static: bool, hand_branch: bool,
                 predict: Callable[[np.ndarray], Intrinsics], beside: bool) -> None:
        """Hold no lens yet.

        Args:
            lens_frames: the engine's ``lens_frames`` (0: never hold a lens).
            static: a fixed camera (``camera_motion: static``).
            hand_branch: the hands come from the model's hand branch (no lens is held).
            predict: returns the model's intrinsics of one RGB image (a fixed camera's lens).
            beside: a fixed camera's lens is estimated beside the stream (``lens_warmup``).

        """
        self._static = static
        self._holds = lens_frames > 0 and not hand_branch
        self._warmup = (LensWarmup(predict, lens_frames, beside) if static and self._holds
                        else None)
        self.fixed: Intrinsics | None = None  # the lens held, once held

    @property
    def provisional(self) -> bool:
        """Return whether a fixed camera's lens is being estimated (frames came without one)."""
        return self._warmup is not None and self._warmup.offered and self.fixed is None

    def reset(self) -> None:
        """Start a new stream: no lens held."""
        if self._warmup is not None:
            self._warmup.reset()
        self.fixed = None

    def close(self) -> None:
        """Stop a fixed camera's lens estimation."""
        if self._warmup is not None:
            self._warmup.close()  # waits for a prediction still running

    def static_lens(self, image: np.ndarray) -> tuple[Intrinsics, bool] | None:
        """Return a fixed camera's lens for a frame, and whether it is provisional.

        None where no lens is estimated beside the stream. Offers the frame to the estimation
        (``LensWarmup``); once it settled, its lens is held.
        """
        if self._warmup is None:
            return None
        lens, provisional = self._warmup.lens(image)
        if not provisional:
            self.fixed = lens
        return lens, provisional

    def hold(self, frames: list[PreparedFrame], used: torch.Tensor) -> torch.Tensor:
        """Return a moving camera's first block's intrinsics as one lens, held for the stream.

        Args:
            frames: the block's frames.
            used: (1, S, 3, 3) the intrinsics the model used, model-input pixels.

        Returns:
            ``used``, or with a lens to hold, its median for every frame (held in ``fixed`` in
            source pixels, and given to the frames after it). Unchanged with given intrinsics,
            a fixed camera (``static_lens``), a lens held already, or none to hold.

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
