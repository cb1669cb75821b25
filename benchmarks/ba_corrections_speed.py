"""Per-frame cost of live pose corrections against the length of the correction history.

    python benchmarks/ba_corrections_speed.py [--sizes 1000 10000 30000] [--frames 300]
        [--every 10] [--keep 32] [--repeats 3]

For each history size N (corrections of N refined keyframes, 0.1 s apart) live frames follow
the newest keyframe and a BA result lands every ``--every`` frames (re-refining the newest
keyframes and adding one, so a blend is always running). Prints ``correct_live`` ms per frame
for the old per-frame path (the whole history sorted, stacked and interpolated on each frame),
for ``CorrectionTrack`` holding the whole history, and for ``CorrectionTrack`` pruned to the
keyframes a binary keyframe pool still holds (``--keep`` newest), plus each one's cost of
folding in a BA result (best of ``--repeats`` runs: other work on the machine only ever adds
time). Figures, not a test: they depend on the machine.
"""

import argparse
import time

from infinihand_ros.ba.config import CorrectionConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.corrections import geodesic
from infinihand_ros.ba.corrections import interpolate_corrections
from infinihand_ros.ba.corrections import keyframe_corrections
import numpy as np
from scipy.spatial.transform import Rotation

#: Keyframe spacing (ns): 10 FPS, every frame a keyframe.
FRAME_NS = 100_000_000
#: Keyframes per BA result (a pool selection of N = 32, K = 3).
KEYFRAMES_PER_CALL = 11
#: Pause after filling the history (s): BLAS threads woken by the batched inverse go idle.
IDLE_S = 0.5


class _HistoryBefore:
    """The correction history as it was kept before pruning: a dict, sorted on every query."""

    def __init__(self, blend_ns: int) -> None:
        self.by_time: dict[int, np.ndarray] = {}
        self.blend_ns = blend_ns
        self.last_live = np.eye(4)
        self.pending = False
        self.blend: tuple[int, np.ndarray] | None = None

    def update(self, times_ns: np.ndarray, T_refined: np.ndarray, T_raw: np.ndarray) -> None:
        for time_ns, correction in zip(times_ns, keyframe_corrections(T_refined, T_raw)):
            self.by_time[int(time_ns)] = correction
        self.pending = self.blend_ns > 0

    def correct_live(self, time_ns: int, T_raw: np.ndarray) -> np.ndarray:
        keys = np.array(sorted(self.by_time))
        target = interpolate_corrections(keys, np.stack([self.by_time[k] for k in keys]),
                                         np.array([time_ns]))[0]
        if self.pending:
            self.blend, self.pending = (time_ns, self.last_live), False
        live = target
        if self.blend is not None:
            fraction = (time_ns - self.blend[0]) / self.blend_ns
            if fraction < 1.0:
                live = geodesic(self.blend[1], target, max(fraction, 0.0))
            else:
                self.blend = None
        self.last_live = live
        return live @ T_raw


def _random_corrections(rng: np.random.Generator, count: int) -> np.ndarray:
    """Return ``count`` small rigid corrections (count, 4, 4)."""
    out = np.tile(np.eye(4), (count, 1, 1))
    out[:, :3, :3] = Rotation.from_rotvec(rng.normal(0.0, 0.01, (count, 3))).as_matrix()
    out[:, :3, 3] = rng.normal(0.0, 0.02, (count, 3))
    return out


def measure(history, size: int, frames: int, every: int, keep: int | None,
            rng: np.random.Generator) -> tuple[float, float]:
    """Return (correct_live ms per frame, ms per BA result) with ``size`` keyframes refined."""
    eye = np.tile(np.eye(4), (size, 1, 1))
    history.update(np.arange(size) * FRAME_NS, _random_corrections(rng, size), eye)
    time.sleep(IDLE_S)
    live_s, update_s, updates, newest = 0.0, 0.0, 0, size - 1
    for frame in range(frames):
        if frame % every == every - 1:
            newest += 1
            times = np.arange(newest - KEYFRAMES_PER_CALL + 1, newest + 1) * FRAME_NS
            start = time.perf_counter()
            history.update(times, _random_corrections(rng, len(times)), eye[:len(times)])
            if keep is not None:
                history.prune((newest - keep + 1) * FRAME_NS)
            update_s += time.perf_counter() - start
            updates += 1
        start = time.perf_counter()
        history.correct_live((newest + 1) * FRAME_NS + frame * 1_000_000, np.eye(4))
        live_s += time.perf_counter() - start
    return 1e3 * live_s / frames, 1e3 * update_s / max(updates, 1)


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1000, 10000, 30000])
    parser.add_argument('--frames', type=int, default=300)
    parser.add_argument('--every', type=int, default=10, help='frames between BA results')
    parser.add_argument('--keep', type=int, default=32, help='keyframes kept by pruning')
    parser.add_argument('--repeats', type=int, default=3, help='runs per cell (best shown)')
    args = parser.parse_args()
    counts = (args.frames, args.every, args.keep, args.repeats)
    if min(args.sizes) < KEYFRAMES_PER_CALL or min(counts) < 1:
        parser.error(f'need sizes >= {KEYFRAMES_PER_CALL} and frames, every, keep, repeats >= 1')
    blend_s = CorrectionConfig().blend_s
    print(f'correct_live ms/frame (ms per BA result); blend {blend_s} s, a result every '
          f'{args.every} frames, {args.frames} frames, best of {args.repeats}')
    print(f'{"history":>8} | {"before (dict, sort/frame)":>26} | {"track, unpruned":>18} | '
          f'{"track, pruned to " + str(args.keep):>20}')
    for size in args.sizes:
        cells = []
        for make, keep in ((lambda: _HistoryBefore(int(blend_s * 1e9)), None),
                           (lambda: CorrectionTrack(blend_s), None),
                           (lambda: CorrectionTrack(blend_s), args.keep)):
            runs = [measure(make(), size, args.frames, args.every, keep,
                            np.random.default_rng(repeat)) for repeat in range(args.repeats)]
            per_frame, per_update = np.min(np.array(runs), axis=0)
            cells.append(f'{per_frame:.3f} ({per_update:.3f})')
        print(f'{size:>8} | {cells[0]:>26} | {cells[1]:>18} | {cells[2]:>20}')


if __name__ == '__main__':
    main()
