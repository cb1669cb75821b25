"""Feeding refined keyframe poses back: per-keyframe corrections, interpolated by timestamp.

A correction is the 4x4 rigid or similarity transform ``D = T_refined @ T_raw^-1`` that maps a
keyframe's raw camera-to-world pose onto its refined one (``T_refined = D @ T_raw``). Between two
refined keyframes a < t < b the correction follows the geodesic
``D_t = D_a Exp(u Log(D_a^-1 D_b))`` with ``u`` from the timestamps; frames before the oldest
refined keyframe take its correction and frames after the newest (the live frames) take the
newest. The raw trajectory is never modified: corrections are applied on read.

Live frames (published as they arrive) do not jump when a BA call lands: from the first live
frame after an update, their correction moves along the geodesic from the correction published
last to the newest one over ``blend_s`` seconds of frame time (BA.md, "Feeding refined poses
back"). ``corrections``/``correct`` always give the newest estimate (for BA's initial poses and
for evaluation); only ``correct_live`` blends.

On an unbounded stream the track is told what it may forget: ``prune(keep_from_ns)`` drops the
corrections no query from that stamp on can use (a blend keeps its own start), and
``max_entries`` caps the history; per-frame cost never depends on how much is held.
"""

from dataclasses import dataclass

from infinihand_ros.ba.keyframe import rescaled
from infinihand_ros.ba.lie import skew
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.validation import as_array
import numpy as np
from scipy import linalg
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class Corrections:
    """One BA call's corrections.

    Attributes:
        times_ns: (K,) keyframe stamps.
        corrections: (K, 4, 4) rigid corrections ``T_refined @ T_submitted^-1``.

    """

    times_ns: np.ndarray
    corrections: np.ndarray


def keyframe_corrections(T_refined: np.ndarray, T_raw: np.ndarray) -> np.ndarray:
    """Return corrections (K, 4, 4) ``T_refined @ T_raw^-1`` of camera-to-world poses (K, 4, 4)."""
    return np.asarray(T_refined, dtype=np.float64) @ np.linalg.inv(T_raw)


def similarity_log(transform: np.ndarray) -> np.ndarray:
    """Matrix logarithm (4, 4) of one rigid or similarity transform (rotation below pi).

    Closed form: ``sR = exp(B)`` with ``B = log(s) I + [omega]x``; the translation part ``u``
    solves ``W u = t`` with ``W = int_0^1 exp(tau B) dtau``, read from the exponential of the
    block matrix ``[[B, I], [0, 0]]``.
    """
    scaled = transform[:3, :3]
    scale = np.cbrt(np.linalg.det(scaled))
    omega = Rotation.from_matrix(scaled / scale).as_rotvec()
    generator = np.log(scale) * np.eye(3) + skew(omega)
    block = np.zeros((6, 6))
    block[:3, :3] = generator
    block[:3, 3:] = np.eye(3)
    integral = linalg.expm(block)[:3, 3:]
    out = np.zeros((4, 4))
    out[:3, :3] = generator
    out[:3, 3] = np.linalg.solve(integral, transform[:3, 3])
    return out


def geodesic(start: np.ndarray, end: np.ndarray, fraction: float | np.ndarray) -> np.ndarray:
    """Return ``start Exp(u Log(start^-1 end))`` between transforms (4, 4) at fractions u.

    A scalar ``fraction`` gives one transform (4, 4); fractions (T,) give (T, 4, 4).
    """
    step = similarity_log(np.linalg.inv(start) @ end)
    return start @ linalg.expm(np.asarray(fraction, dtype=np.float64)[..., None, None] * step)


def interpolate_corrections(key_times_ns: np.ndarray, key_corrections: np.ndarray,
                            times_ns: np.ndarray) -> np.ndarray:
    """Return the correction (T, 4, 4) of each query time.

    Args:
        key_times_ns: (K,) strictly increasing timestamps of refined keyframes (ns).
        key_corrections: (K, 4, 4) their corrections.
        times_ns: (T,) query timestamps (ns), any order.

    Raises:
        InputError: for no keyframe, mismatched lengths or non-increasing keyframe times.

    """
    keys = np.asarray(key_times_ns, dtype=np.int64)
    corrections = as_array(key_corrections, 'key corrections', (len(keys), 4, 4))
    if len(keys) == 0:
        raise InputError('interpolate_corrections: no refined keyframe; run BA first or use '
                         'the raw poses')
    if np.any(np.diff(keys) <= 0):
        raise InputError('interpolate_corrections: keyframe times must be strictly increasing')
    return _interpolate(keys, corrections, np.asarray(times_ns, dtype=np.int64).reshape(-1))


def _interpolate(keys: np.ndarray, corrections: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Interpolate checked keyframe corrections (K >= 1, increasing ``keys``) at ``times`` (T,)."""
    previous = np.searchsorted(keys, times, side='right') - 1
    out = corrections[np.clip(previous, 0, len(keys) - 1)]
    segment = np.clip(previous, 0, max(len(keys) - 2, 0))
    inside = (times > keys[0]) & (times < keys[-1])
    for index in np.unique(segment[inside]):
        chosen = inside & (segment == index)
        fraction = (times[chosen] - keys[index]) / (keys[index + 1] - keys[index])
        out[chosen] = geodesic(corrections[index], corrections[index + 1], fraction)
    return out


@dataclass(frozen=True)
class _Blend:
    """A blend of live corrections in progress: from ``origin`` at ``start_ns`` to ``target``.

    ``step`` is ``Log(origin^-1 target)``, kept so that each live frame costs one exponential.
    """

    start_ns: int
    origin: np.ndarray  # (4, 4) the live correction published before the update
    target: np.ndarray  # (4, 4) the correction the blend moves to
    step: np.ndarray  # (4, 4) similarity_log(origin^-1 @ target)


def _blend_towards(start_ns: int, origin: np.ndarray, target: np.ndarray) -> _Blend:
    """Return a blend from ``origin`` (4, 4) at ``start_ns`` to ``target`` (4, 4)."""
    return _Blend(start_ns, origin, target, similarity_log(np.linalg.inv(origin) @ target))


class CorrectionTrack:
    """Corrections of the refined keyframes that can still matter, keyed by keyframe timestamp.

    The corrections are kept in two arrays sorted by stamp and merged on each ``update`` (once
    per BA call), so queries never sort or stack: ``correct_live`` costs the same whatever the
    stream's length. What the track holds is bounded by ``prune`` (entries no query at or after
    a stamp can use are dropped, results for those queries stay exactly the same) and, as a
    safety net, by ``max_entries``.
    """

    def __init__(self, blend_s: float = 0.0, max_entries: int | None = None) -> None:
        """Start without corrections (raw poses pass through unchanged).

        Args:
            blend_s: live corrections move to a new BA result over this much frame time (s);
                0 applies it at once.
            max_entries: most corrections kept (the oldest go first), or None for no limit
                (then only ``prune`` bounds the history). Queries older than the oldest kept
                keyframe take its correction.

        Raises:
            ValueError: for a negative ``blend_s`` or a ``max_entries`` below 2.

        """
        if blend_s < 0:
            raise ValueError(f'CorrectionTrack: blend_s must be >= 0 s, got {blend_s}')
        if max_entries is not None and max_entries < 2:
            raise ValueError(f'CorrectionTrack: max_entries must be >= 2 or None, got '
                             f'{max_entries}')
        self._blend_ns = int(round(blend_s * 1e9))
        self._max_entries = max_entries
        self._times = np.zeros(0, dtype=np.int64)  # (N,) strictly increasing stamps (ns)
        self._values = np.zeros((0, 4, 4))  # (N, 4, 4) their corrections
        self._last_live = np.eye(4)
        self._blend_pending = False
        self._blend: _Blend | None = None

    def __len__(self) -> int:
        """Return the number of corrected keyframes held."""
        return len(self._times)

    @property
    def oldest_ns(self) -> int | None:
        """Stamp of the oldest correction held (ns), or None before any BA result."""
        return int(self._times[0]) if len(self._times) else None

    @property
    def newest_ns(self) -> int | None:
        """Stamp of the newest correction held (ns), or None before any BA result."""
        return int(self._times[-1]) if len(self._times) else None

    def update(self, times_ns: np.ndarray, T_refined: np.ndarray, T_raw: np.ndarray,
               scale: float = 1.0) -> None:
        """Record refined poses (K, 4, 4) of keyframes with raw poses (K, 4, 4) at ``times_ns``.

        The poses' translations are at metric ``scale`` (metres per unit of the raw poses the
        track corrects): the correction is kept for raw poses in those units, so it stays right
        when the scale moves later.

        A call supersedes the corrections inside its span: a keyframe refined again takes the new
        correction (within one call, the last one given wins), and an earlier call's keyframe
        between this call's first and last is dropped, so the frames there follow this call's
        corrections alone (two calls' solutions interleaved would zig-zag). The next
        ``correct_live`` call starts a blend from the live correction published last.

        Raises:
            InputError: when the stamps (K,) do not match the poses.

        """
        times = np.asarray(times_ns, dtype=np.int64).reshape(-1)
        corrections = keyframe_corrections(rescaled(T_refined, 1.0 / scale),
                                           rescaled(T_raw, 1.0 / scale)).reshape(-1, 4, 4)
        if len(times) != len(corrections):
            raise InputError(f'CorrectionTrack.update: {len(times)} stamps for '
                             f'{len(corrections)} poses; pass one stamp per keyframe')
        new_times, last = np.unique(times[::-1], return_index=True)
        new_values = corrections[::-1][last]
        kept = ~(np.isin(self._times, new_times, assume_unique=True)
                 | ((self._times > new_times[0]) & (self._times < new_times[-1])))
        old_times, old_values = self._times[kept], self._values[kept]
        where = np.searchsorted(old_times, new_times)
        self._times = np.insert(old_times, where, new_times)
        self._values = np.insert(old_values, where, new_values, axis=0)
        if self._max_entries is not None and len(self._times) > self._max_entries:
            self._keep_from_index(len(self._times) - self._max_entries)
        self._blend_pending = self._blend_ns > 0

    def prune(self, keep_from_ns: int) -> int:
        """Drop the corrections no query at or after ``keep_from_ns`` can use.

        Kept: every correction from ``keep_from_ns`` on, the newest one before it (the start
        of the segment that ``keep_from_ns`` falls in) and always the newest one, so
        ``corrections``/``correct`` at stamps >= ``keep_from_ns`` and every later live
        correction (blends included) are exactly what they were. A stream should pass the
        oldest stamp it may still query: the oldest keyframe left in the binary keyframe pool
        (or, for live frames only, the newest refined stamp). ``is_refined`` of dropped stamps
        answers False.

        Args:
            keep_from_ns: the oldest stamp that will still be queried (ns).

        Returns:
            The number of corrections dropped.

        """
        first = int(np.searchsorted(self._times, int(keep_from_ns), side='right')) - 1
        return self._keep_from_index(max(first, 0))

    def _keep_from_index(self, first: int) -> int:
        """Drop the ``first`` oldest corrections; return how many were dropped."""
        first = min(first, max(len(self._times) - 1, 0))
        if first > 0:  # copies: the dropped entries' memory is released
            self._times = self._times[first:].copy()
            self._values = self._values[first:].copy()
        return first

    def is_refined(self, time_ns: int) -> bool:
        """Return whether the keyframe at ``time_ns`` was refined by an earlier BA call."""
        index = int(np.searchsorted(self._times, int(time_ns)))
        return index < len(self._times) and int(self._times[index]) == int(time_ns)

    def is_covered(self, time_ns: int) -> bool:
        """Return whether ``time_ns`` lies between the oldest and newest refined keyframes.

        Such a time's correction comes from BA results (a refined keyframe's, or interpolated
        between two), so a BA call that holds it fixed keeps continuity with them.
        """
        return bool(len(self._times)) and int(self._times[0]) <= int(time_ns) <= int(
            self._times[-1])

    def corrections(self, times_ns: np.ndarray) -> np.ndarray:
        """Return each time's correction (T, 4, 4); identity before any BA call."""
        times = np.asarray(times_ns, dtype=np.int64).reshape(-1)
        if not len(self._times):
            return np.broadcast_to(np.eye(4), (len(times), 4, 4)).copy()
        return _interpolate(self._times, self._values, times)

    def correct(self, times_ns: np.ndarray, T_raw: np.ndarray) -> np.ndarray:
        """Return corrected camera-to-world poses (T, 4, 4) of raw poses (T, 4, 4)."""
        return self.corrections(times_ns) @ np.asarray(T_raw, dtype=np.float64)

    def live_correction(self, time_ns: int) -> np.ndarray:
        """Return the correction (4, 4) to publish for a live frame at ``time_ns``.

        Live frames come in time order. After an update, the first live frame keeps the
        correction published last; later ones move geodesically to the newest correction and
        reach it ``blend_s`` after that frame.
        """
        time_ns = int(time_ns)
        target = self._correction_at(time_ns)
        if self._blend_pending:
            self._blend = _blend_towards(time_ns, self._last_live, target)
            self._blend_pending = False
        live = target
        if self._blend is not None:
            fraction = (time_ns - self._blend.start_ns) / self._blend_ns
            if fraction < 1.0:
                if not np.array_equal(target, self._blend.target):  # a frame before the newest
                    self._blend = _blend_towards(self._blend.start_ns, self._blend.origin,
                                                 target)
                live = self._blend.origin @ linalg.expm(
                    np.float64(max(fraction, 0.0)) * self._blend.step)
            else:
                self._blend = None
        self._last_live = live
        return live

    def correct_live(self, time_ns: int, T_raw: np.ndarray) -> np.ndarray:
        """Return the corrected camera-to-world pose (4, 4) of a live frame's raw pose (4, 4)."""
        return self.live_correction(time_ns) @ np.asarray(T_raw, dtype=np.float64)

    def _correction_at(self, time_ns: int) -> np.ndarray:
        """Return one stamp's correction (4, 4); live frames after the newest keyframe are O(1)."""
        if not len(self._times):
            return np.eye(4)
        if time_ns >= self._times[-1]:
            return self._values[-1].copy()
        return _interpolate(self._times, self._values, np.array([time_ns], dtype=np.int64))[0]
