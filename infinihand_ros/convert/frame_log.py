"""The count of every frame a conversion skipped or had to adjust, by reason."""

from collections import Counter
from dataclasses import dataclass
from dataclasses import field


@dataclass
class FrameLog:
    """Frames read, frames skipped by reason and warnings by reason, for one episode.

    Attributes:
        read: source frames read (usable or not).
        skipped: reason -> number of source frames dropped for it.
        warnings: reason -> number of frames kept despite it (e.g. no CameraInfo).

    """

    read: int = 0
    skipped: Counter = field(default_factory=Counter)
    warnings: Counter = field(default_factory=Counter)

    def skip(self, reason: str) -> None:
        """Count one dropped frame."""
        self.skipped[reason] += 1

    def warn(self, reason: str) -> None:
        """Count one kept frame with a problem."""
        self.warnings[reason] += 1

    @property
    def num_skipped(self) -> int:
        """Return how many source frames were dropped."""
        return sum(self.skipped.values())
