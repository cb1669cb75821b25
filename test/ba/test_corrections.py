"""Pose corrections: exact at refined keyframes, geodesic between them, latest for live frames."""

from infinihand_ros.ba.corrections import CorrectionTrack
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
