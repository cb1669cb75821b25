"""Pose corrections: exact at refined keyframes, geodesic between them, latest for live frames."""

from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.corrections import geodesic
from infinihand_ros.ba.corrections import interpolate_corrections
from infinihand_ros.ba.corrections import keyframe_corrections
from infinihand_ros.ba.corrections import similarity_log
from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
import numpy as np
import pytest
from scipy import linalg
from scipy.spatial.transform import Rotation


def _pose(yaw_deg: float, translation: list[float], scale: float = 1.0) -> np.ndarray:
    """Return a 4x4 similarity: rotation about z, then scale, then translation."""
    out = geometry.make_transform(Rotation.from_euler('z', yaw_deg, degrees=True).as_matrix(),
                                  translation)
    out[:3, :3] *= scale
    return out


def test_geodesic_midpoint_and_clamped_ends() -> None:
    """Halfway between 0 and 20 degrees is 10; before/after the keyframes the ends are held."""
    keys = np.array([100, 200])
    corrections = np.stack([_pose(0.0, [0, 0, 0]), _pose(20.0, [0, 0, 0])])
    out = interpolate_corrections(keys, corrections, np.array([50, 100, 150, 200, 900]))
    np.testing.assert_allclose(out[[0, 1]], np.stack([corrections[0]] * 2), atol=1e-12)
    np.testing.assert_allclose(out[[3, 4]], np.stack([corrections[1]] * 2), atol=1e-12)
    np.testing.assert_allclose(out[2], _pose(10.0, [0, 0, 0]), atol=1e-9)


def test_similarity_interpolation_is_log_linear_in_scale() -> None:
    """Scales 1 and 4 meet at 2 halfway; pure translations interpolate linearly."""
    keys = np.array([0, 10, 20])
    corrections = np.stack([_pose(0, [0, 0, 0]), _pose(0, [0, 0, 0], scale=4.0),
                            _pose(0, [1.0, 0, 0], scale=4.0)])
    out = interpolate_corrections(keys, corrections, np.array([5, 15]))
    assert np.cbrt(np.linalg.det(out[0, :3, :3])) == pytest.approx(2.0)
    np.testing.assert_allclose(out[1, :3, 3], [0.5, 0, 0], atol=1e-9)


def test_track_reproduces_refined_keyframes_and_corrects_live_frames(rng) -> None:
    """Refined keyframes come back exactly; a later live frame takes the newest correction."""
    track = CorrectionTrack()
    raw = np.stack([_pose(float(a), rng.normal(size=3)) for a in rng.uniform(-30, 30, 4)])
    np.testing.assert_allclose(track.correct(np.arange(4), raw), raw)
    refined = np.stack([_pose(5.0, [0.1, 0, 0]) @ pose for pose in raw[:3]])
    track.update(np.array([0, 1, 2]), refined, raw[:3])
    assert track.is_refined(1) and not track.is_refined(3)
    corrected = track.correct(np.arange(4), raw)
    np.testing.assert_allclose(corrected[:3], refined, atol=1e-9)
    np.testing.assert_allclose(corrected[3], _pose(5.0, [0.1, 0, 0]) @ raw[3], atol=1e-9)
    # Refining keyframe 2 again replaces its correction.
    track.update(np.array([2]), raw[2:3], raw[2:3])
    np.testing.assert_allclose(track.correct(np.array([2]), raw[2:3])[0], raw[2], atol=1e-12)
    np.testing.assert_allclose(keyframe_corrections(refined, raw[:3])[0],
                               _pose(5.0, [0.1, 0, 0]), atol=1e-9)


def test_bad_keyframe_times_are_refused() -> None:
    """Non-increasing keyframe times and an empty set raise with the fix."""
    eye = np.stack([np.eye(4)] * 2)
    with pytest.raises(InputError, match='strictly increasing'):
        interpolate_corrections(np.array([5, 5]), eye, np.array([1]))
    with pytest.raises(InputError, match='run BA first'):
        interpolate_corrections(np.zeros(0), np.zeros((0, 4, 4)), np.array([1]))


def test_log_matches_the_general_matrix_logarithm(rng) -> None:
    """The closed-form Sim(3) log equals scipy's logm on random similarities."""
    for _ in range(5):
        transform = _pose(float(rng.uniform(-120, 120)), rng.normal(size=3),
                          scale=float(rng.uniform(0.5, 2.0)))
        turn = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
        transform[:3, :3] = turn @ transform[:3, :3]
        np.testing.assert_allclose(similarity_log(transform), np.real(linalg.logm(transform)),
                                   atol=1e-9)


def _distance(first: np.ndarray, second: np.ndarray) -> float:
    """Return the norm of the Sim(3) log between two corrections."""
    return float(np.linalg.norm(similarity_log(np.linalg.inv(first) @ second)))


def test_live_corrections_blend_in_without_jumps() -> None:
    """A new result is reached over blend_s in steps of at most the blend step, then held."""
    frame_ns, blend_s = 100_000_000, 0.3
    track = CorrectionTrack(blend_s)
    first, second = _pose(4.0, [0.2, 0, 0], 1.1), _pose(-6.0, [0, 0.3, 0.1], 0.9)
    track.update(np.array([0]), first, np.eye(4)[None])
    live = [track.live_correction(t) for t in range(frame_ns, 6 * frame_ns, frame_ns)]
    track.update(np.array([5 * frame_ns]), second, np.eye(4)[None])
    live += [track.live_correction(t) for t in range(6 * frame_ns, 12 * frame_ns, frame_ns)]
    np.testing.assert_allclose(live[0], np.eye(4), atol=1e-12)  # blend starts where it was
    step = frame_ns * 1e-9 / blend_s
    limit = max(_distance(np.eye(4), first), _distance(first, second)) * step + 1e-9
    assert max(_distance(a, b) for a, b in zip(live[:-1], live[1:])) <= limit
    # 0.3 s after the first live frame of each update, the newest correction holds exactly.
    for index in (3, 4, 8, 9, 10):
        np.testing.assert_allclose(live[index], second if index >= 5 else first, atol=1e-9)
    assert _distance(live[6], second) > 0.01, 'the second result must blend in, not jump'
    np.testing.assert_allclose(track.correct_live(20 * frame_ns, np.eye(4)), second, atol=1e-12)


def test_update_during_a_blend_continues_from_the_published_correction() -> None:
    """A result landing mid-blend starts from the half-blended correction, not from an end."""
    track = CorrectionTrack(blend_s=1.0)
    track.update(np.array([0]), _pose(10.0, [0, 0, 0])[None], np.eye(4)[None])
    track.live_correction(1_000_000)
    halfway = track.live_correction(501_000_000)
    np.testing.assert_allclose(halfway, _pose(5.0, [0, 0, 0]), atol=1e-9)
    track.update(np.array([2]), _pose(-10.0, [0, 0, 0])[None], np.eye(4)[None])
    np.testing.assert_allclose(track.live_correction(601_000_000), halfway, atol=1e-12)
    np.testing.assert_allclose(track.live_correction(1_101_000_000), _pose(-2.5, [0, 0, 0]),
                               atol=1e-9)
    # The best estimate (initial poses, evaluation) never blends.
    np.testing.assert_allclose(track.corrections(np.array([601_000_000]))[0],
                               _pose(-10.0, [0, 0, 0]), atol=1e-12)


def test_negative_blend_time_is_refused() -> None:
    """A negative blend time names the value."""
    with pytest.raises(ValueError, match='got -0.1'):
        CorrectionTrack(blend_s=-0.1)


class _OldTrack:
    """The correction history as kept before pruning (a dict sorted on every query): the oracle."""

    def __init__(self, blend_s: float) -> None:
        self.by_time: dict[int, np.ndarray] = {}
        self.blend_ns = int(round(blend_s * 1e9))
        self.last_live, self.pending, self.blend = np.eye(4), False, None

    def update(self, times_ns: np.ndarray, T_refined: np.ndarray, T_raw: np.ndarray) -> None:
        for time_ns, correction in zip(times_ns, keyframe_corrections(T_refined, T_raw)):
            self.by_time[int(time_ns)] = correction
        self.pending = self.blend_ns > 0

    def corrections(self, times_ns: np.ndarray) -> np.ndarray:
        keys = np.array(sorted(self.by_time))
        return interpolate_corrections(keys, np.stack([self.by_time[k] for k in keys]), times_ns)

    def live_correction(self, time_ns: int) -> np.ndarray:
        target = self.corrections(np.array([time_ns]))[0]
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
        return live


def _small_corrections(rng: np.random.Generator, count: int) -> np.ndarray:
    """Return ``count`` random small similarities (count, 4, 4)."""
    return np.stack([_pose(float(rng.normal(0, 2)), rng.normal(0, 0.05, 3),
                           float(np.exp(rng.normal(0, 0.02)))) for _ in range(count)])


def _pool_like_updates(rng: np.random.Generator, count: int, frame_ns: int):
    """Yield (stamps, corrections, oldest stamp still queried) of ``count`` BA results.

    Each result refines 4 consecutive keyframes: the 3 newest refined before (again) and a new
    one, like a pool that keeps its last selections; the oldest of them is the prune horizon.
    Corrections are drawn from a bank of random small similarities.
    """
    bank = _small_corrections(rng, 64)
    for call in range(count):
        stamps = np.arange(call, call + 4) * frame_ns
        yield stamps, bank[rng.integers(0, len(bank), 4)], int(stamps[0])


def test_prune_keeps_every_result_from_the_horizon_on() -> None:
    """Pruning drops what no later query uses; queries from the horizon on are unchanged."""
    track = CorrectionTrack()
    keys = np.arange(1, 7) * 100
    track.update(keys, np.stack([_pose(float(k) / 20, [k / 1e3, 0, 0]) for k in keys]),
                 np.tile(np.eye(4), (6, 1, 1)))
    queries = np.arange(250, 900, 7)
    before = track.corrections(queries)
    assert track.prune(250) == 1 and len(track) == 5  # 200 stays: 250 lies between 200 and 300
    assert track.oldest_ns == 200 and track.newest_ns == 600
    np.testing.assert_array_equal(track.corrections(queries), before)
    assert not track.is_refined(100) and track.is_refined(200)
    assert track.prune(300) == 1 and track.prune(300) == 0  # a key at the horizon is kept
    assert track.prune(10**18) == 3 and len(track) == 1  # the newest always stays
    np.testing.assert_array_equal(track.corrections(np.array([10**17])), before[-1:])


def test_max_entries_bounds_the_history_and_is_checked() -> None:
    """The oldest corrections go first beyond max_entries; a limit below 2 names the value."""
    track = CorrectionTrack(max_entries=3)
    for time_ns in range(10):
        track.update(np.array([time_ns]), _pose(float(time_ns), [0, 0, 0])[None],
                     np.eye(4)[None])
    assert len(track) == 3 and track.oldest_ns == 7
    with pytest.raises(ValueError, match='got 1'):
        CorrectionTrack(max_entries=1)


def test_update_merges_out_of_order_and_repeated_stamps() -> None:
    """Stamps in any order are kept sorted; a stamp repeated in one call keeps its last pose."""
    track = CorrectionTrack()
    eye = np.tile(np.eye(4), (3, 1, 1))
    track.update(np.array([300, 100, 300]), np.stack([_pose(1, [0, 0, 0]), _pose(2, [0, 0, 0]),
                                                      _pose(3, [0, 0, 0])]), eye)
    track.update(np.array([200]), _pose(4, [0, 0, 0])[None], eye[:1])
    np.testing.assert_allclose(track.corrections(np.array([100, 200, 300])),
                               np.stack([_pose(a, [0, 0, 0]) for a in (2, 4, 3)]), atol=1e-12)
    with pytest.raises(InputError, match='2 stamps for 3 poses'):
        track.update(np.array([1, 2]), eye, eye)


def test_pruned_track_matches_the_old_unbounded_history(rng) -> None:
    """Live (blended) and best corrections equal the old dict-based history's, bit for bit."""
    frame_ns = 100_000_000
    track, old = CorrectionTrack(blend_s=0.3), _OldTrack(blend_s=0.3)
    for stamps, corrections, horizon in _pool_like_updates(rng, 60, frame_ns):
        for history in (track, old):
            history.update(stamps, corrections, np.tile(np.eye(4), (4, 1, 1)))
        track.prune(horizon)
        for offset in (0.5, 1.5, 2.5):  # live frames after the newest keyframe, mid-blend
            time_ns = int(stamps[-1] + offset * frame_ns)
            np.testing.assert_array_equal(track.live_correction(time_ns),
                                          old.live_correction(time_ns))
        queries = np.linspace(horizon, stamps[-1] + frame_ns, 9).astype(np.int64)
        np.testing.assert_array_equal(track.corrections(queries), old.corrections(queries))
    assert len(track) == 4 and len(old.by_time) == 63


def test_history_stays_bounded_over_a_long_run(rng) -> None:
    """20,000 BA results, pruned to the pool: a few entries held, frames in range unchanged."""
    frame_ns = 50_000_000
    track, history = CorrectionTrack(), {}  # blends: see the test above
    largest = 0
    for call, (stamps, corrections, horizon) in enumerate(
            _pool_like_updates(rng, 20_000, frame_ns)):
        track.update(stamps, corrections, np.tile(np.eye(4), (4, 1, 1)))
        track.prune(horizon)
        history.update(zip(stamps.tolist(), corrections))
        track.correct_live(int(stamps[-1]) + frame_ns, np.eye(4))
        largest = max(largest, len(track))
        if call % 4_000 == 3_999:  # the old behaviour: interpolate the whole history
            keys = np.array(sorted(history))
            queries = np.arange(horizon, stamps[-1] + 2 * frame_ns, frame_ns // 3)
            np.testing.assert_array_equal(
                track.corrections(queries),
                interpolate_corrections(keys, np.stack([history[k] for k in keys]), queries))
    assert largest == 4 and len(history) == 20_003


def test_a_call_supersedes_the_corrections_inside_its_span() -> None:
    """An older call's keyframe between a newer call's first and last is dropped.

    Its frames then follow the newer call alone (two solutions interleaved would zig-zag);
    corrections outside the newer span stay.
    """
    track = CorrectionTrack()
    raw = np.stack([np.eye(4)] * 4)
    track.update(np.array([0, 100, 200, 300]),
                 np.stack([_pose(0, [0, 0, 0]), _pose(9, [0, 0, 0]), _pose(0, [0, 0, 0]),
                           _pose(0, [0, 0, 0])]), raw)
    track.update(np.array([0, 200]), np.stack([_pose(0, [0, 0, 0]), _pose(2, [0, 0, 0])]),
                 raw[:2])
    assert not track.is_refined(100) and track.is_refined(300)
    assert track.is_covered(100) and not track.is_covered(301)
    np.testing.assert_allclose(track.corrections(np.array([100]))[0], _pose(1, [0, 0, 0]),
                               atol=1e-12)
    np.testing.assert_allclose(track.corrections(np.array([300]))[0], np.eye(4), atol=1e-12)
