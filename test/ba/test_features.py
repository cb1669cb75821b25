"""Per-keyframe feature cache: computed once per frame, bounded by the keyframe pool."""

from dataclasses import replace

from ba_builders import synth_keyframe
import cv2
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import TrackingConfig
from infinihand_ros.ba.correspondences import build_problem
from infinihand_ros.ba.features import compute_features
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.features import trackable_mask
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_pool import BinaryKeyframePool
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

TRIGGER, STRIDE = 8, 3


def _small_keyframe(frame_id: int, image: np.ndarray) -> KeyframeInput:
    """Return a 48x64 keyframe with a textured image, no hands and depth 2 m."""
    intrinsics = Intrinsics(50.0, 50.0, 32.0, 24.0, 64, 48)
    return KeyframeInput(frame_id, 1000 * frame_id, image, np.full((48, 64), 2.0, np.float32),
                         np.eye(4), intrinsics, np.zeros((48, 64), dtype=bool))


def test_long_stream_computes_each_frame_once_and_stays_bounded(rng) -> None:
    """Over 400 frames each selected frame is computed once; the cache never outgrows the pool."""
    image = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    pool = BinaryKeyframePool(TRIGGER, STRIDE)
    cache = FeatureCache(TrackingConfig())
    selected_ids, requested = set(), 0
    for frame_id in range(400):
        if pool.push(frame_id, _small_keyframe(frame_id, image)) is None:
            continue
        for entry in pool.last_selection:
            cache.features(entry.state)
            requested += 1
            selected_ids.add(entry.frame_id)
        cache.retain(pool.frame_ids())
        assert len(cache) <= len(pool) <= TRIGGER + 1
    assert cache.computed == len(selected_ids)
    assert requested > 1.5 * cache.computed, 'retained keyframes were not reused'
    # A new sequence reusing frame ids (new stamps) never gets the old features.
    reused = replace(_small_keyframe(0, image), timestamp_ns=-1)
    kept = pool.frame_ids()[0]
    assert cache.features(replace(reused, frame_id=kept)).timestamp_ns == -1


def test_cached_features_equal_fresh_ones_and_build_the_same_problem() -> None:
    """Reusing cached features changes nothing: same features, same problem as without a cache."""
    config = BAConfig()
    sequence = SyntheticSequence(SynthConfig(), seed=7, num_frames=10)
    keyframes = [synth_keyframe(sequence.frame(index)) for index in range(0, 10, 3)]
    cache = FeatureCache(config.tracking)
    first = cache.features(keyframes[0])
    assert cache.features(keyframes[0]) is first and cache.computed == 1
    fresh = compute_features(keyframes[0], config.tracking)
    np.testing.assert_array_equal(first.corners, fresh.corners)
    np.testing.assert_array_equal(first.orb_descriptors, fresh.orb_descriptors)
    poses = np.stack([keyframe.T_world_cam for keyframe in keyframes])
    fixed = np.arange(len(keyframes)) == 0
    cached = build_problem(keyframes, poses, fixed, config.tracking, config.solver, cache)
    again = build_problem(keyframes, poses, fixed, config.tracking, config.solver, cache)
    plain = build_problem(keyframes, poses, fixed, config.tracking, config.solver)
    assert cache.computed == len(keyframes)
    for problem in (again, plain):
        np.testing.assert_array_equal(problem.obs_xy, cached.obs_xy)
        np.testing.assert_array_equal(problem.host_xy, cached.host_xy)


def test_cache_with_other_settings_is_refused() -> None:
    """A cache made with different tracking settings would give stale features: refused."""
    config = BAConfig()
    sequence = SyntheticSequence(SynthConfig(), seed=7, num_frames=4)
    keyframes = [synth_keyframe(sequence.frame(index)) for index in (0, 3)]
    cache = FeatureCache(TrackingConfig(max_corners=50))
    with pytest.raises(InputError, match='same tracking settings'):
        build_problem(keyframes, np.stack([k.T_world_cam for k in keyframes]),
                      np.array([True, False]), config.tracking, config.solver, cache)


def test_trackable_mask_matches_a_whole_image_dilation(rng) -> None:
    """Dilating only around the hands equals dilating the whole mask, also at the border."""
    config = TrackingConfig(hand_margin_px=5)
    keyframe = _small_keyframe(0, rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
    hands = np.zeros((48, 64), dtype=bool)
    hands[0:6, 58:64] = True
    hands[20:24, 30:33] = True
    depth = keyframe.depth.copy()
    depth[40:, :10] = np.nan
    keyframe = replace(keyframe, hand_mask=hands, depth=depth)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (11, 11))
    expected = (cv2.dilate(hands.astype(np.uint8), kernel) == 0) & np.isfinite(depth)
    np.testing.assert_array_equal(trackable_mask(keyframe, config), expected * 255)
    assert trackable_mask(replace(keyframe, hand_mask=np.zeros_like(hands)), config).any()
