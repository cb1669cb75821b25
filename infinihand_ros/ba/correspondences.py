"""Correspondences between selected keyframes, turned into a ``BAProblem``.

KLT (pyramidal Lucas-Kanade with a forward-backward check) links consecutive keyframes into
tracks, topped up in each keyframe with its best corners away from the tracked points; ORB
matching re-links keyframes 2..``orb_max_gap`` places apart. Corners, ORB features and masks
come from ``ba.features`` (cached per keyframe across calls). Every pairing passes
fundamental-matrix RANSAC. Hand pixels (dilated masks) and pixels without a valid model depth
are excluded. A track's host is its oldest keyframe; its depth prior
and initial inverse depth come from the host's depth map.
"""

from dataclasses import dataclass

import cv2
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.config import TrackingConfig
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.features import KeyframeFeatures
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe import StreamLens
from infinihand_ros.ba.problem import BAProblem
from infinihand_ros.core.errors import InputError
import numpy as np
from scipy import spatial

#: Fewer point pairs than this skip RANSAC's model fit (all pairs are dropped).
MIN_RANSAC_PAIRS = 8


@dataclass
class _Tracks:
    """Growing list of (track, keyframe, pixel) observations; track ids are dense from 0."""

    track: list
    frame: list
    xy: list
    count: int = 0

    def add(self, frame: int, xy: np.ndarray, track: np.ndarray | None = None) -> np.ndarray:
        """Add observations in ``frame``; new track ids when ``track`` is None; return ids."""
        if track is None:
            track = np.arange(self.count, self.count + len(xy))
            self.count += len(xy)
        self.track.append(track)
        self.frame.append(np.full(len(xy), frame))
        self.xy.append(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return track


def _inside(valid: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Return (N,) bool: the rounded pixel lies in the image and on a trackable pixel."""
    col, row = np.round(xy[:, 0]).astype(int), np.round(xy[:, 1]).astype(int)
    height, width = valid.shape
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    out = np.zeros(len(xy), dtype=bool)
    out[inside] = valid[row[inside], col[inside]] > 0
    return out


def ransac_inliers(xy_a: np.ndarray, xy_b: np.ndarray, threshold_px: float) -> np.ndarray:
    """Return (N,) bool inliers of a fundamental-matrix RANSAC between pixel pairs (N, 2)."""
    if len(xy_a) < MIN_RANSAC_PAIRS:
        return np.zeros(len(xy_a), dtype=bool)
    _, mask = cv2.findFundamentalMat(xy_a.astype(np.float32), xy_b.astype(np.float32),
                                     cv2.FM_RANSAC, threshold_px, 0.999)
    return np.zeros(len(xy_a), dtype=bool) if mask is None else mask.ravel().astype(bool)


def klt_track(gray_a: np.ndarray, gray_b: np.ndarray, xy_a: np.ndarray,
              config: TrackingConfig) -> tuple[np.ndarray, np.ndarray]:
    """Track pixels (N, 2) from image a to b; return (xy_b (N, 2), ok (N,) bool).

    A point is kept when LK converges both ways and returns within ``fb_threshold_px``.
    """
    if len(xy_a) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=bool)
    window = (config.klt_window_px, config.klt_window_px)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, config.klt_iterations,
                config.klt_epsilon_px)
    start = xy_a.astype(np.float32).reshape(-1, 1, 2)
    forward, ok_f, _ = cv2.calcOpticalFlowPyrLK(gray_a, gray_b, start, None, winSize=window,
                                                maxLevel=config.klt_levels, criteria=criteria)
    back, ok_b, _ = cv2.calcOpticalFlowPyrLK(gray_b, gray_a, forward, None, winSize=window,
                                             maxLevel=config.klt_levels, criteria=criteria)
    fb_error = np.linalg.norm((back - start).reshape(-1, 2), axis=-1)
    ok = (ok_f.ravel() > 0) & (ok_b.ravel() > 0) & (fb_error < config.fb_threshold_px)
    return forward.reshape(-1, 2).astype(np.float64), ok


def _top_up(features: KeyframeFeatures, existing: np.ndarray,
            config: TrackingConfig) -> np.ndarray:
    """Return the best cached corners (N, 2) at least the corner distance from ``existing``."""
    wanted = config.max_corners - len(existing)
    corners = features.corners
    if wanted <= 0 or len(corners) == 0:
        return np.zeros((0, 2))
    if len(existing):
        gap, _ = spatial.cKDTree(existing).query(
            corners, distance_upper_bound=config.min_corner_distance_px)
        corners = corners[gap >= config.min_corner_distance_px]
    return corners[:wanted]


def _klt_tracks(features: list[KeyframeFeatures], config: TrackingConfig,
                tracks: _Tracks) -> None:
    """Chain KLT tracks through consecutive keyframes (new corners topped up in each)."""
    ids = tracks.add(0, _top_up(features[0], np.zeros((0, 2)), config))
    xy = tracks.xy[-1]
    for frame in range(1, len(features)):
        moved, ok = klt_track(features[frame - 1].gray, features[frame].gray, xy, config)
        ok &= _inside(features[frame].valid, moved)
        ok[ok] = ransac_inliers(xy[ok], moved[ok], config.ransac_threshold_px)
        tracks.add(frame, moved[ok], ids[ok])
        fresh = _top_up(features[frame], moved[ok], config)
        ids = np.r_[ids[ok], tracks.add(frame, fresh)]
        xy = np.r_[moved[ok], fresh]


def _orb_links(features: list[KeyframeFeatures], config: TrackingConfig,
               tracks: _Tracks) -> None:
    """Add two-view tracks from ORB matches between keyframes 2..orb_max_gap places apart."""
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)
    for later in range(len(features)):
        for earlier in range(max(0, later - config.orb_max_gap), later - 1):
            first, second = features[earlier], features[later]
            if first.orb_descriptors is None or second.orb_descriptors is None:
                continue
            matches = [m for m in matcher.match(first.orb_descriptors, second.orb_descriptors)
                       if m.distance <= config.orb_max_hamming]
            index = np.array([(m.queryIdx, m.trainIdx) for m in matches], dtype=int)
            index = index.reshape(-1, 2)
            xy_a, xy_b = first.orb_xy[index[:, 0]], second.orb_xy[index[:, 1]]
            keep = ransac_inliers(xy_a, xy_b, config.ransac_threshold_px)
            ids = tracks.add(earlier, xy_a[keep])
            tracks.add(later, xy_b[keep], ids)


def build_problem(keyframes: list[KeyframeInput], T_world_cam: np.ndarray, fixed: np.ndarray,
                  tracking: TrackingConfig, solver: SolverConfig,
                  cache: FeatureCache | None = None,
                  lens: StreamLens | None = None) -> BAProblem:
    """Match the keyframes and return the BA problem over them.

    Args:
        keyframes: the selected keyframes, oldest first.
        T_world_cam: (K, 4, 4) initial poses (the current best, i.e. corrected, estimates).
        fixed: (K,) bool gauge.
        tracking: correspondence settings.
        solver: solver settings (for the depth prior's sigma).
        cache: per-keyframe features kept from earlier calls, made with ``tracking``; None
            computes every keyframe's features afresh.
        lens: the stream's lens from earlier calls: the start and prior centre of this call's
            shared lens, whose prior sigmas shrink as 1 / sqrt(1 + its calls); None: the
            keyframes' median pinhole. Keyframes that are all ``calibrated`` hold the lens.

    Raises:
        InputError: when the cache was made with other tracking settings, or no feature
            track links the keyframes.

    Returns:
        A problem with relative-pose priors between consecutive keyframes from the initial
        poses: earlier BA results for keyframes refined before, the estimator's motion since
        the newest refined keyframe for new ones (raw poses far apart carry the network's
        drift between them).

    """
    if cache is not None and cache.config != tracking:
        raise InputError(f'build_problem: the feature cache was made with {cache.config}, not '
                         f'{tracking}; create the cache with the same tracking settings')
    cache = FeatureCache(tracking) if cache is None else cache
    features = [cache.features(keyframe) for keyframe in keyframes]
    tracks = _Tracks([], [], [])
    _klt_tracks(features, tracking, tracks)
    _orb_links(features, tracking, tracks)
    if not tracks.track or sum(len(t) for t in tracks.track) == 0:
        raise InputError(f'BA: no feature tracks between keyframes '
                         f'{[k.frame_id for k in keyframes]} (textureless images, or hand '
                         'masks covering them); their poses stay uncorrected')
    track, frame, xy = (np.concatenate(tracks.track), np.concatenate(tracks.frame),
                        np.concatenate(tracks.xy))
    order = np.lexsort((frame, track))
    track, frame, xy = track[order], frame[order], xy[order]
    first = np.r_[True, track[1:] != track[:-1]]
    views = np.bincount(track, minlength=tracks.count)
    host_frame, host_xy, host_track = frame[first], xy[first], track[first]
    depth_maps = np.stack([keyframe.depth for keyframe in keyframes])
    depth = depth_maps[host_frame, np.round(host_xy[:, 1]).astype(int),
                       np.round(host_xy[:, 0]).astype(int)].astype(np.float64)
    usable = (views[host_track] >= 2) & np.isfinite(depth) & (depth > 0)
    new_id = np.full(tracks.count, -1)
    new_id[host_track[usable]] = np.arange(np.count_nonzero(usable))
    observed = ~first & (new_id[track] >= 0)
    inv_depth = 1.0 / depth[usable]
    initial = np.asarray(T_world_cam, dtype=np.float64)
    pairs = np.c_[np.arange(len(keyframes) - 1), np.arange(1, len(keyframes))]
    # One lens for the selection: the keyframes' median pinhole, refined by the solver.
    pinhole = np.median(np.stack([k.intrinsics.matrix() for k in keyframes]), axis=0)
    sigma = np.array([solver.lens_focal_sigma, solver.lens_k1_sigma])
    start = np.zeros(2)
    if all(keyframe.calibrated for keyframe in keyframes):
        sigma = np.zeros(2)
    elif lens is not None:
        start = np.array([np.log(lens.focal_px / pinhole[0, 0]), lens.k1])
        sigma = sigma / np.sqrt(1.0 + lens.calls)
    return BAProblem(
        T_world_cam=initial,
        intrinsics=np.broadcast_to(pinhole, (len(keyframes), 3, 3)).copy(),
        fixed=np.asarray(fixed, dtype=bool), host=host_frame[usable],
        host_xy=host_xy[usable], inv_depth=inv_depth, prior_inv_depth=inv_depth,
        prior_sigma=solver.depth_prior_rel_sigma * inv_depth, obs_track=new_id[track[observed]],
        obs_frame=frame[observed], obs_xy=xy[observed], obs_weight=np.ones(observed.sum()),
        prior_pairs=pairs, prior_T_rel=np.linalg.inv(initial[pairs[:, 0]]) @ initial[pairs[:, 1]],
        lens_sigma=sigma, lens=start)
