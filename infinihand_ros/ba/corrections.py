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
"""

from dataclasses import dataclass

from infinihand_ros.ba.lie import skew
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.validation import as_array
import numpy as np
from scipy import linalg
from scipy.spatial.transform import Rotation


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
    times = np.asarray(times_ns, dtype=np.int64).reshape(-1)
    if len(keys) == 0:
        raise InputError('interpolate_corrections: no refined keyframe; run BA first or use '
                         'the raw poses')
    if np.any(np.diff(keys) <= 0):
        raise InputError('interpolate_corrections: keyframe times must be strictly increasing')
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
    """A blend of live corrections in progress: from ``origin`` at ``start_ns`` on."""

    start_ns: int
    origin: np.ndarray  # (4, 4) the live correction published before the update


class CorrectionTrack:
    """Corrections of every keyframe refined so far, keyed by keyframe timestamp."""

    def __init__(self, blend_s: float = 0.0) -> None:
        """Start without corrections (raw poses pass through unchanged).

        Args:
            blend_s: live corrections move to a new BA result over this much frame time (s);
                0 applies it at once.

        Raises:
            ValueError: for a negative ``blend_s``.

        """
        if blend_s < 0:
            raise ValueError(f'CorrectionTrack: blend_s must be >= 0 s, got {blend_s}')
        self._blend_ns = int(round(blend_s * 1e9))
        self._by_time: dict[int, np.ndarray] = {}
        self._last_live = np.eye(4)
        self._blend_pending = False
        self._blend: _Blend | None = None

    def __len__(self) -> int:
        """Return the number of corrected keyframes."""
        return len(self._by_time)

    def update(self, times_ns: np.ndarray, T_refined: np.ndarray, T_raw: np.ndarray) -> None:
        """Record refined poses (K, 4, 4) of keyframes with raw poses (K, 4, 4) at ``times_ns``.

        A keyframe refined again replaces its earlier correction. The next ``correct_live``
        call starts a blend from the live correction published last.
        """
        corrections = keyframe_corrections(T_refined, T_raw)
        for time_ns, correction in zip(np.asarray(times_ns, dtype=np.int64), corrections):
            self._by_time[int(time_ns)] = correction
        self._blend_pending = self._blend_ns > 0

    def is_refined(self, time_ns: int) -> bool:
        """Return whether the keyframe at ``time_ns`` was refined by an earlier BA call."""
        return int(time_ns) in self._by_time

    def corrections(self, times_ns: np.ndarray) -> np.ndarray:
        """Return each time's correction (T, 4, 4); identity before any BA call."""
        times = np.asarray(times_ns, dtype=np.int64).reshape(-1)
        if not self._by_time:
            return np.broadcast_to(np.eye(4), (len(times), 4, 4)).copy()
        keys = np.array(sorted(self._by_time))
        return interpolate_corrections(keys, np.stack([self._by_time[k] for k in keys]), times)

    def correct(self, times_ns: np.ndarray, T_raw: np.ndarray) -> np.ndarray:
        """Return corrected camera-to-world poses (T, 4, 4) of raw poses (T, 4, 4)."""
        return self.corrections(times_ns) @ np.asarray(T_raw, dtype=np.float64)

    def live_correction(self, time_ns: int) -> np.ndarray:
        """Return the correction (4, 4) to publish for a live frame at ``time_ns``.

        Live frames come in time order. After an update, the first live frame keeps the
        correction published last; later ones move geodesically to the newest correction and
        reach it ``blend_s`` after that frame.
        """
        target = self.corrections(np.array([time_ns]))[0]
        if self._blend_pending:
            self._blend = _Blend(int(time_ns), self._last_live)
            self._blend_pending = False
        live = target
        if self._blend is not None:
            fraction = (int(time_ns) - self._blend.start_ns) / self._blend_ns
            if fraction < 1.0:
                live = geodesic(self._blend.origin, target, max(fraction, 0.0))
            else:
                self._blend = None
        self._last_live = live
        return live

    def correct_live(self, time_ns: int, T_raw: np.ndarray) -> np.ndarray:
        """Return the corrected camera-to-world pose (4, 4) of a live frame's raw pose (4, 4)."""
        return self.live_correction(time_ns) @ np.asarray(T_raw, dtype=np.float64)
