"""Every hand the hand source found in an episode: written, or dropped for a named reason.

The hand source counts, over the frames the engine was given, the hands it found (MediaPipe's,
or the hand branch's) and those it dropped by cause (``dropped_*`` in its statistics: under
``hands.min_confidence``, a hand seen twice, not confirmed by the guard). The rest reach the
engine's results, where a hand is written as valid or is invalid for a reason of
``lerobot_features`` (not placed in the world, a degenerate palm). So ``found`` is ``written``
plus the sum of ``dropped``. Source frames the resampling did not use were never looked at
(``EpisodeReport.frames_in`` against ``frames_used``).
"""

from collections import Counter
from collections.abc import Iterable
from collections.abc import Mapping
from dataclasses import dataclass
from dataclasses import field
from typing import Final

from infinihand_ros.convert.lerobot_features import NOT_DETECTED

#: The hand source's drop counters (``HandSource.statistics``) and their reasons.
SOURCE_DROPS: Final = {
    'dropped_confidence': 'under hands.min_confidence',
    'dropped_duplicate': 'a hand seen twice',
    'dropped_verify': 'not confirmed by MediaPipe (hands.verify)',
}


@dataclass(frozen=True)
class HandAccounting:
    """Where an episode's found hands went.

    Attributes:
        found: hands the hand source found in the frames the engine was given.
        written: hands written as valid.
        dropped: reason -> hands found but not written.

    """

    found: int = 0
    written: int = 0
    dropped: dict[str, int] = field(default_factory=dict)

    @property
    def adds_up(self) -> bool:
        """Return whether every found hand is written or dropped for a counted reason."""
        return self.found == self.written + sum(self.dropped.values())

    def line(self) -> str:
        """Return the accounting as one readable line."""
        reasons = ''.join(f', {count} {reason}' for reason, count in self.dropped.items())
        return f'hands found {self.found}: written {self.written}{reasons}'


def account_hands(source_before: Mapping[str, object], source_after: Mapping[str, object],
                  written: int, invalid: Iterable[Mapping[str, str]]) -> HandAccounting:
    """Return the accounting of one episode.

    Args:
        source_before: the hand source's statistics when the episode started.
        source_after: its statistics after the episode's last result.
        written: valid hands in the engine's results (one result per frame given).
        invalid: per result, side name -> why its hand is invalid (``frame_values``).

    """
    def counted(key: str) -> int:
        return int(source_after.get(key, 0)) - int(source_before.get(key, 0))

    dropped = {reason: counted(key) for key, reason in SOURCE_DROPS.items() if counted(key)}
    later = Counter(reason for reasons in invalid for reason in reasons.values()
                    if reason != NOT_DETECTED)
    return HandAccounting(counted('found'), written, {**dropped, **later})
