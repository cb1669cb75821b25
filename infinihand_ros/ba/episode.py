"""One bundle adjustment over the whole episode, when an offline stream ends.

The stream's BA refines windows of the binary keyframe pool while frames come in. An offline run
sees the whole recording, so when its stream ends (``StreamingEngine.refined``) the episode is
refined once as a whole: every keyframe it had (``EpisodeKeyframes``: at most ``max_keyframes``,
spread evenly over it), starting from the stream's final trajectory and lens, with the
streaming BA's problem (Huber loss and outlier gate, depth priors that hold the metric scale,
the oldest keyframe fixed as the gauge, relative-pose priors from the start), solved to
convergence (``irls_iterations``).

The refinement is used only where it improves on the stream (``judge``), otherwise the stream's
poses stand:
- the tracks it never saw (every ``holdout_every``-th) cost less with it than with the start, by
  at least ``min_gain`` of the start's Huber cost and by at least ``min_z`` standard errors of
  that decrease (over the held-out tracks: a track's observations share its depth, so tracks
  are the independent samples). A start the images cannot clearly improve on stands: a second
  solve over the same images mostly adds its own noise;
- no keyframe moves further than the images support: ``max_move_share`` of the path of the
  keyframes' start poses, or, for a camera that hardly moves, the move its images cannot see at
  all (one that shifts the scene at the keyframe's median depth by less than ``huber_px``). The
  stream's trajectory lies within a few per cent of the path of an SfM reference on real clips,
  so a keyframe moved by a large share of the path is another solution (a moving object taken
  for the scene, a wrong minimum), not a correction of this one.
"""

from dataclasses import dataclass
from dataclasses import replace
import logging
import time
from typing import Any, Final

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import EpisodeConfig
from infinihand_ros.ba.correspondences import build_problem
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe import StreamLens
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.ba.validation import held_out_costs
from infinihand_ros.ba.validation import MIN_HELD_OUT_OBSERVATIONS
from infinihand_ros.ba.validation import split_holdout
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.geometry import rotation_angle_deg
import numpy as np

logger = logging.getLogger(__name__)

#: Held-out share of the episode's tracks when the solver's check is off (``holdout_every`` 0):
#: the episode's refinement is never used unchecked.
HOLDOUT_EVERY: Final = 5
#: Smallest move bound (m): a keyframe with no depth on a still camera may not move at all.
MIN_BOUND_M: Final = 1e-9


class EpisodeKeyframes:
    """The keyframes of one episode, at most ``max_keyframes``, spread evenly over it."""

    def __init__(self, max_keyframes: int) -> None:
        """Keep every keyframe offered until there are more than ``max_keyframes``."""
        self.max_keyframes = max_keyframes
        self._kept: list[KeyframeInput] = []
        self._stride = 1  # every stride-th keyframe offered is kept
        self._offered = 0

    def __len__(self) -> int:
        """Return the number of keyframes kept."""
        return len(self._kept)

    def add(self, keyframe: KeyframeInput) -> None:
        """Offer the episode's next keyframe (in time order); drop every other one when full."""
        if self._offered % self._stride == 0:
            self._kept.append(keyframe)
        self._offered += 1
        if len(self._kept) > self.max_keyframes:
            self._kept = self._kept[::2]
            self._stride *= 2

    def keyframes(self) -> list[KeyframeInput]:
        """Return the kept keyframes, oldest first."""
        return list(self._kept)


@dataclass(frozen=True)
class EpisodeRefinement:
    """What the whole-episode refinement did.

    Attributes:
        accepted: its poses are used (``judge``); otherwise the stream's stand.
        reason: why, in words.
        keyframes: keyframes refined.
        held_out_observations: observations of the held-out tracks.
        initial_cost: Huber cost per held-out observation with the stream's poses (px^2).
        refined_cost: the same with the refinement's.
        z: the decrease in standard errors.
        max_move_m: the largest keyframe move (m) ...
        move_bound_m: ... and the most that keyframe could move (m).
        max_rotation_deg: the largest keyframe rotation (deg).
        seconds: wall time (matching, solve and check).
        timestamps_ns: (K,) the keyframes' stamps.
        T_start: (K, 4, 4) their poses from the stream (camera-to-world, m).
        T_refined: (K, 4, 4) the refinement's poses.

    """

    accepted: bool
    reason: str
    keyframes: int
    held_out_observations: int = 0
    initial_cost: float = float('nan')
    refined_cost: float = float('nan')
    z: float = float('nan')
    max_move_m: float = 0.0
    move_bound_m: float = 0.0
    max_rotation_deg: float = 0.0
    seconds: float = 0.0
    timestamps_ns: np.ndarray | None = None
    T_start: np.ndarray | None = None
    T_refined: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        """Return the figures (no poses) as JSON-ready data."""
        return {'accepted': self.accepted, 'reason': self.reason, 'keyframes': self.keyframes,
                'held_out_observations': self.held_out_observations,
                'held_out_cost': [self.initial_cost, self.refined_cost], 'z': self.z,
                'max_move_m': self.max_move_m, 'move_bound_m': self.move_bound_m,
                'max_rotation_deg': self.max_rotation_deg, 'seconds': self.seconds}


def decrease_z(before: np.ndarray, after: np.ndarray, track: np.ndarray) -> float:
    """Return the mean decrease of per-observation costs (M,) over its standard error.

    The error is that of a ratio estimator over the tracks (``track`` (M,): each observation's
    track), whose observations are not independent of each other.
    """
    _, track = np.unique(track, return_inverse=True)
    count = np.bincount(track)
    decrease = np.bincount(track, before - after)
    mean = decrease.sum() / count.sum()
    tracks = len(count)
    if tracks < 2:
        return float('nan')
    spread = np.sqrt(tracks / (tracks - 1) * np.sum((decrease - mean * count)**2))
    error = spread / count.sum()
    if error > 0:
        return float(mean / error)
    return float(np.sign(mean) * np.inf) if mean else 0.0


def judge(before: np.ndarray, after: np.ndarray, track: np.ndarray, moves_m: np.ndarray,
          bounds_m: np.ndarray, config: EpisodeConfig) -> tuple[bool, str]:
    """Return (accepted, reason) for a refinement (see the module).

    Args:
        before: (M,) Huber cost of each held-out observation with the start's poses.
        after: (M,) the same with the refinement's.
        track: (M,) each observation's held-out track.
        moves_m: (K,) how far each keyframe moved (m).
        bounds_m: (K,) how far each may move (m).
        config: the thresholds.

    """
    if len(before) < MIN_HELD_OUT_OBSERVATIONS:
        return False, (f'{len(before)} held-out observations, fewer than '
                       f'{MIN_HELD_OUT_OBSERVATIONS}: nothing to judge by')
    start, refined = float(np.mean(before)), float(np.mean(after))
    gain = 1.0 - refined / start if start > 0 else 0.0
    z = decrease_z(before, after, track)
    change = f"{abs(100 * gain):.1f} % {'lower' if gain >= 0 else 'higher'}"
    costs = f'held-out cost {start:.3f} -> {refined:.3f} px^2 ({change}, z {z:.1f})'
    if not gain >= config.min_gain:
        return False, f'{costs}: less than {100 * config.min_gain:.0f} % lower'
    if not z >= config.min_z:
        return False, f'{costs}: a decrease within {config.min_z:g} standard errors'
    worst = int(np.argmax(np.asarray(moves_m) / np.asarray(bounds_m)))
    if moves_m[worst] > bounds_m[worst]:
        return False, (f'{costs}, but keyframe {worst} moves {moves_m[worst]:.4f} m, more than '
                       f'the {bounds_m[worst]:.4f} m the images support')
    return True, costs


def move_bounds(keyframes: list[KeyframeInput], T_start: np.ndarray, huber_px: float,
                config: EpisodeConfig) -> np.ndarray:
    """Return how far (m) each keyframe may move: a share of the path, or what is invisible."""
    centres = np.asarray(T_start)[:, :3, 3]
    path = float(np.linalg.norm(np.diff(centres, axis=0), axis=-1).sum())
    invisible = np.array([_median_depth(k) * huber_px / k.intrinsics.fx for k in keyframes])
    return np.maximum(np.maximum(config.max_move_share * path, invisible), MIN_BOUND_M)


def _median_depth(keyframe: KeyframeInput) -> float:
    """Return the median of a keyframe's valid depths (m), 0 without any."""
    depth = keyframe.depth[np.isfinite(keyframe.depth) & (keyframe.depth > 0)]
    return float(np.median(depth)) if depth.size else 0.0


def refine_episode(keyframes: list[KeyframeInput], T_start: np.ndarray,
                   lens: StreamLens | None, config: BAConfig) -> EpisodeRefinement:
    """Refine the episode's keyframes (oldest first, one metric scale) from poses (K, 4, 4).

    ``lens`` is the stream's (its BA calls'), None for the keyframes' pinhole. A refinement
    that cannot be made (no tracks between the keyframes) is returned refused.
    """
    start_time = time.perf_counter()
    T_start = np.asarray(T_start, dtype=np.float64)
    count = len(keyframes)
    stamps = np.array([keyframe.timestamp_ns for keyframe in keyframes], dtype=np.int64)
    fixed = np.zeros(count, dtype=bool)
    fixed[0] = True
    solver = config.solver
    try:
        problem = build_problem(keyframes, T_start, fixed, config.tracking, solver, None, lens)
        fit, held = split_holdout(problem, solver.holdout_every or HOLDOUT_EVERY)
        result = BundleAdjuster(replace(solver, irls_iterations=config.episode.irls_iterations)
                                ).solve(fit)
    except (InfiniHandError, np.linalg.LinAlgError) as exc:
        logger.warning('whole-episode BA failed; the stream poses stand: %s', exc)
        return EpisodeRefinement(False, f'failed: {exc}', count,
                                 seconds=time.perf_counter() - start_time)
    before, after = np.zeros(0), np.zeros(0)
    if len(held.obs_track) >= MIN_HELD_OUT_OBSERVATIONS:
        before = held_out_costs(held, T_start, problem.lens, solver)
        after = held_out_costs(held, result.T_world_cam, result.lens, solver)
    moves = np.linalg.norm(result.T_world_cam[:, :3, 3] - T_start[:, :3, 3], axis=-1)
    bounds = move_bounds(keyframes, T_start, solver.huber_px, config.episode)
    accepted, reason = judge(before, after, held.obs_track, moves, bounds, config.episode)
    worst = int(np.argmax(moves / bounds))
    rotations = rotation_angle_deg(result.T_world_cam[:, :3, :3], T_start[:, :3, :3])
    judged = len(before) > 0
    logger.info('whole-episode BA over %d keyframes %s: %s', count,
                'accepted' if accepted else 'refused', reason)
    return EpisodeRefinement(
        accepted, reason, count, len(before),
        float(np.mean(before)) if judged else np.nan, float(np.mean(after)) if judged else np.nan,
        decrease_z(before, after, held.obs_track) if judged else np.nan, float(moves[worst]),
        float(bounds[worst]), float(np.max(rotations)), time.perf_counter() - start_time, stamps,
        T_start, result.T_world_cam)
