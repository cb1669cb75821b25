"""How often the geometry branch runs on a live stream: chosen from what it costs on this machine.

With ``geometry_interval: auto`` (the default) the engine times, as it runs, a frame answered
without the geometry branch (``frame``: the push of a tracked frame, hand detection included) and
the geometry branch itself (``geometry``: its run on one frame, time spent paused while a frame is
pushed left out), and keeps the input's frame period (the median time between the arrivals of the
images a live caller saw, pushed or not, ``StreamingEngine.observe_input``, else between the stamps
of the frames pushed). With the geometry branch on every k-th frame, a frame costs on average
``frame + geometry / k``; ``Pacer`` keeps the smallest k (from 1 to ``max_geometry_interval``)
whose cost stays within ``utilisation`` of the frame period, so a live stream is answered with
margin, and a machine that could keep up with a larger interval never falls into dropping frames.
It goes to a smaller k only when that one stays within ``relax`` of the budget (no flapping between
two intervals). A number for ``geometry_interval`` fixes it instead.
"""

from collections import deque
from dataclasses import dataclass
import math
import statistics
import threading
from typing import Final

from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.errors import ConfigError

#: The interval a paced engine starts with, before it has measured anything.
START_INTERVAL: Final = 3
#: Timings kept per kind (their median is the cost), and stamps kept for the frame period.
WINDOW: Final = 15
#: Frames of each kind timed before the interval moves from its start.
MIN_SAMPLES: Final = 3
#: Frame periods longer than this are gaps (a pause), not the input rate.
MAX_PERIOD_S: Final = 1.0


@dataclass(frozen=True)
class PacingConfig:
    """How a paced engine (``geometry_interval: auto``) chooses its interval.

    Attributes:
        utilisation: the share of the input's frame period the engine may fill on average
            (the rest is margin for the rest of the machine and for bursts), in (0, 1].
        relax: a smaller interval is taken only where its cost stays within this share of
            the budget (hysteresis), in (0, 1].
        max_geometry_interval: the largest interval chosen (the tracker carries the frames
            between; beyond it, frames are dropped by a live caller instead).

    """

    utilisation: float = 0.7
    relax: float = 0.85
    max_geometry_interval: int = 16

    def __post_init__(self) -> None:
        for name in ('utilisation', 'relax'):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise ConfigError(f'engine.pacing.{name} must be in (0, 1], got {value!r}')
        require_at_least('engine.pacing', 1, max_geometry_interval=self.max_geometry_interval)


@dataclass(frozen=True)
class PacingState:
    """What the pacer measured and chose (for ``statistics`` and diagnostics).

    Attributes:
        paced: the interval is chosen from measured cost (False: fixed by the settings).
        geometry_interval: the geometry branch runs on every this-many-th frame now.
        geometry_lag: frames after its own whose answers come before its outputs are taken in.
        frame_ms: median cost of a frame answered without the geometry branch (None: not yet).
        geometry_ms: median cost of the geometry branch on one frame (None: not yet).
        period_ms: the input's frame period (None: not known yet).
        utilisation: ``frame + geometry / interval`` over the period (None: not known yet).

    """

    paced: bool
    geometry_interval: int
    geometry_lag: int
    frame_ms: float | None
    geometry_ms: float | None
    period_ms: float | None
    utilisation: float | None

    def as_dict(self) -> dict[str, object]:
        """Return the state as plain values."""
        return dict(self.__dict__)


class Pacer:
    """Keeps the geometry interval of a stream within its time budget (or a fixed one)."""

    def __init__(self, interval: int | str, lag: int, config: PacingConfig,
                 applies: bool) -> None:
        """Start at ``interval`` (a number: fixed) or, for 'auto', at ``START_INTERVAL``.

        Args:
            interval: the engine's ``geometry_interval``.
            lag: the engine's ``geometry_lag`` (held below the interval chosen).
            config: the engine's ``pacing`` settings.
            applies: the interval is used at all (per-frame mode, a tracked moving camera,
                hands from outside the model); False: never paced.

        """
        self.paced = interval == 'auto' and applies
        self._config = config
        self._lag = lag
        self._frames: deque[float] = deque(maxlen=WINDOW)
        self._geometry: deque[float] = deque(maxlen=WINDOW)
        self._arrivals: deque[int] = deque(maxlen=WINDOW + 1)
        self._pushed: deque[int] = deque(maxlen=WINDOW + 1)
        self._lock = threading.Lock()  # geometry costs come from the engine's worker thread
        self.interval = START_INTERVAL if interval == 'auto' else int(interval)

    def reset(self) -> None:
        """Start a new stream: its frame period is measured again (the costs are kept)."""
        with self._lock:
            self._arrivals.clear()
            self._pushed.clear()

    @property
    def lag(self) -> int:
        """Return the geometry lag for the current interval (below it, where it is above 1)."""
        return min(self._lag, max(self.interval - 1, 0))

    def arrived(self, arrival_ns: int) -> None:
        """Note when an image arrived at a live caller (monotonic clock; from any thread)."""
        with self._lock:
            self._arrivals.append(arrival_ns)

    def pushed(self, timestamp_ns: int) -> None:
        """Note the stamp of a frame the engine took; it gives the period without arrivals."""
        with self._lock:
            self._pushed.append(timestamp_ns)

    def frame_cost(self, seconds: float) -> None:
        """Note how long a frame answered without the geometry branch took; re-choose."""
        with self._lock:
            self._frames.append(seconds)
            self._choose()

    def geometry_cost(self, seconds: float) -> None:
        """Note how long the geometry branch took on one frame; re-choose."""
        with self._lock:
            self._geometry.append(seconds)
            self._choose()

    def _period_s(self) -> float | None:
        """Return the input's frame period (median step), None before two arrivals or stamps."""
        stamps = self._arrivals if len(self._arrivals) >= 2 else self._pushed
        steps = [(b - a) * 1e-9 for a, b in zip(stamps, list(stamps)[1:])]
        steps = [step for step in steps if 0.0 < step <= MAX_PERIOD_S]
        return statistics.median(steps) if steps else None

    def state(self) -> PacingState:
        """Return what was measured and chosen."""
        with self._lock:
            return self._state()

    def _costs(self) -> tuple[float | None, float | None, float | None]:
        """Return the median frame and geometry costs and the frame period, s (lock held)."""
        frame = statistics.median(self._frames) if self._frames else None
        geometry = statistics.median(self._geometry) if self._geometry else None
        return frame, geometry, self._period_s()

    def _state(self) -> PacingState:
        """Return what was measured and chosen (the lock held)."""
        frame, geometry, period = self._costs()
        use = (None if None in (frame, geometry, period)
               else (frame + geometry / self.interval) / period)
        return PacingState(self.paced, self.interval, self.lag,
                           None if frame is None else 1e3 * frame,
                           None if geometry is None else 1e3 * geometry,
                           None if period is None else 1e3 * period, use)

    def _choose(self) -> None:
        """Take the smallest interval whose cost fits the budget (with hysteresis)."""
        if (not self.paced or len(self._frames) < MIN_SAMPLES
                or len(self._geometry) < MIN_SAMPLES):
            return
        frame, geometry, period = self._costs()
        if period is not None:
            self.interval = choose_interval(frame, geometry, period, self.interval,
                                            self._config)


def choose_interval(frame_s: float, geometry_s: float, period_s: float, current: int,
                    config: PacingConfig) -> int:
    """Return the geometry interval for these costs and frame period.

    The smallest interval k with ``frame + geometry / k <= utilisation * period``; one below
    ``current`` only where it stays within ``relax`` of that budget; the largest allowed where
    none fits.
    """
    budget = config.utilisation * period_s
    largest = config.max_geometry_interval
    spare = budget - frame_s
    needed = largest if spare <= 0.0 else max(1, math.ceil(geometry_s / spare - 1e-9))
    needed = min(needed, largest)
    if needed >= current:
        return needed
    # Going down: the smallest interval that fits with the hysteresis margin, not below needed.
    return next((k for k in range(needed, current)
                 if frame_s + geometry_s / k <= config.relax * budget), current)
