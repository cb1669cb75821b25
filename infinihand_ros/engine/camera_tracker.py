"""Per-frame camera tracking: the image-based front end of the pose track.

The network's camera drifts within seconds, and a bundle-adjustment result corrects only the
frames after it arrives, so every frame's pose is measured from the image itself. A reference
frame's corners (off the hands, where the network's depth is valid) are lifted to 3D points in
the reference camera (model units) and followed by pyramidal KLT from the last tracked frame
to each new one (forward-backward checked); PnP with RANSAC on those points gives the frame's
pose relative to the reference, started from the network's relative motion (the prior) and
refined on the inliers. When too few points hold (a textureless, blurred or covered frame) the
network's motion since the previous frame is used instead (``predicted``), and the next frame is
tracked from the last tracked one. When the points are lost at once while the new frame is as
sharp as the reference (a cut to another scene, not motion blur), or for ``max_lost_frames`` in
a row, the track restarts on that frame (``reinitialised``: the pose keeps the network's motion
and the frame marks the discontinuity). The reference moves to the current frame once too few
of its points are left: the points still held move with it (so the scene's structure, and with
it the pose, is not re-measured from one depth map each time), rescaled to agree with the new
frame's depth, and new corners away from them fill up to ``max_corners``.

Everything runs on the model-input image (grey, with the model's depth and intrinsics for it),
in the network's model units, so the metric scale and BA corrections apply on top unchanged.

A frame the geometry branch skipped (``engine.geometry_interval``) comes without a network pose
and without depth: it is tracked from the points held (the last pose is the prior and the
fallback), and whatever needs depth (a new reference, a restart) waits for a frame with it;
``needs_depth`` asks the engine for the geometry branch on the next frame (first, when the
tracker is ``lost``). When the geometry branch runs on a frame after its answer went out,
``absorb`` takes its network pose and depth as if they had come with it: a renewal due there
happens on them, and a frame the tracker lost takes the network's motion (for the frames after
it). They may come after a later frame was tracked without them (the engine runs the geometry
branch one frame late): ``moment()``, taken right after the frame, holds what ``absorb`` then
needs, and the renewal happens at that frame, as if the later one had not been seen.
"""

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import replace
import time
from typing import Final

import cv2
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.geometry import invert_transform
from infinihand_ros.core.geometry import make_transform
import numpy as np

#: Per-frame states: measured by PnP; predicted by the network (too few points); a new start.
TRACKING_STATES: Final = ('tracked', 'predicted', 'reinitialised')


@dataclass(frozen=True)
class TrackerConfig:
    """Settings of the per-frame camera tracker (section ``engine.tracker``).

    Attributes:
        enabled: measure each frame's pose from the image (false: the network's poses as they
            are).
        max_corners: corners taken on a reference frame.
        corner_quality: minimum corner quality, relative to the frame's best corner.
        min_corner_distance_px: corners at least this far apart (model-input pixels).
        hand_margin_px: hand boxes grown by this much are never tracked (hands move on
            their own).
        klt_window_px: KLT window size (pixels, odd).
        klt_levels: KLT pyramid levels above the image.
        forward_backward_px: a point is kept only when tracking it back lands this close.
        ransac_px: PnP RANSAC inlier threshold (reprojection error, pixels).
        min_inliers: fewer inliers: the network's motion is used for the frame.
        refresh_fraction: a new reference is taken once fewer than this fraction of the
            reference's points are inliers.
        cut_fraction: a scene cut: fewer than this fraction of the points survive KLT while the
            new frame has at least ``min_inliers`` corners.
        max_step_deg: a PnP pose rotated more than this from the prior is refused (a wrong
            solution); the prior is used.
        blur_ratio: a frame whose sharpness (variance of the Laplacian) is below this fraction
            of the reference's is blurred: losing the points there is no cut.
        max_lost_frames: after this many frames in a row without tracking, the track restarts
            on the next frame with texture.

    """

    enabled: bool = True
    max_corners: int = 200
    corner_quality: float = 0.01
    min_corner_distance_px: float = 7.0
    hand_margin_px: int = 8
    klt_window_px: int = 15
    klt_levels: int = 3
    forward_backward_px: float = 1.0
    ransac_px: float = 2.0
    min_inliers: int = 20
    refresh_fraction: float = 0.5
    cut_fraction: float = 0.2
    max_step_deg: float = 30.0
    blur_ratio: float = 0.5
    max_lost_frames: int = 3

    def __post_init__(self) -> None:
        require_at_least('engine.tracker', 4, max_corners=self.max_corners,
                         min_inliers=self.min_inliers)
        require_at_least('engine.tracker', 0, hand_margin_px=self.hand_margin_px,
                         klt_levels=self.klt_levels)
        require_at_least('engine.tracker', 1, max_lost_frames=self.max_lost_frames)
        require_positive('engine.tracker', corner_quality=self.corner_quality,
                         min_corner_distance_px=self.min_corner_distance_px,
                         forward_backward_px=self.forward_backward_px,
                         ransac_px=self.ransac_px, max_step_deg=self.max_step_deg)
        if self.klt_window_px < 3 or self.klt_window_px % 2 == 0:
            raise ConfigError(f'engine.tracker.klt_window_px must be an odd number >= 3, got '
                              f'{self.klt_window_px}')
        for key in ('corner_quality', 'refresh_fraction', 'cut_fraction', 'blur_ratio'):
            if not 0.0 <= getattr(self, key) < 1.0:
                raise ConfigError(f'engine.tracker.{key} must be in [0, 1), got '
                                  f'{getattr(self, key)}')


@dataclass(frozen=True)
class TrackingView:
    """What the tracker sees of one frame (model-input pixels).

    Attributes:
        gray: (H, W) uint8 grey model-input image.
        depth: returns the (H, W) float32 network depth, model units; called only for a new
            reference frame (the engine runs the depth head there, not on every frame); None
            on a frame the geometry branch skipped.
        intrinsics: the model-input intrinsics the network used.
        content_box: (x0, y0, x1, y1) pixels holding image content (the rest is padding).
        hand_boxes: (N, 4) hand boxes (x0, y0, x1, y1), pixels.

    """

    gray: np.ndarray
    depth: Callable[[], np.ndarray] | None
    intrinsics: Intrinsics
    content_box: tuple[int, int, int, int]
    hand_boxes: np.ndarray


@dataclass(frozen=True)
class TrackedFrame:
    """The tracker's answer for one frame.

    Attributes:
        T_raw: (4, 4) camera-to-world pose, model units.
        state: one of ``TRACKING_STATES``.
        inliers: points that support the pose (0 unless ``tracked``).

    """

    T_raw: np.ndarray
    state: str
    inliers: int


@dataclass(frozen=True)
class TrackerMoment:
    """The tracker right after one frame, for ``CameraTracker.absorb`` after later frames.

    Attributes:
        frames: frames tracked up to it (``CameraTracker.frames``).
        view: the frame the reference's points were in then.
        T_raw: the frame's pose.
        reference: the reference as it was then (its points' pixels in ``view``).
        lost: the frame was not tracked.
        needs_depth: a renewal or restart waited for depth there.

    """

    frames: int
    view: TrackingView
    T_raw: np.ndarray
    reference: '_Reference | None'
    lost: bool
    needs_depth: bool


@dataclass
class _Reference:
    """The frame the points were lifted in, and where they are now."""

    T_raw: np.ndarray  # reference camera-to-world, model units
    points: np.ndarray  # (P, 3) float32, reference camera frame
    pixels: np.ndarray  # (P, 2) float32, in the last tracked frame
    count: int  # points lifted
    sharpness: float  # variance of the reference image's Laplacian


class CameraTracker:
    """Track one stream's camera frame by frame (not thread-safe; ``reset`` between streams)."""

    def __init__(self, config: TrackerConfig) -> None:
        """Start with no reference."""
        self.config = config
        self._lk = {'winSize': (config.klt_window_px, config.klt_window_px),
                    'maxLevel': config.klt_levels,
                    'criteria': (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03)}
        self.reset()

    def reset(self) -> None:
        """Forget the reference and the counts (a new stream)."""
        self._reference: _Reference | None = None
        self._last_view: TrackingView | None = None  # the last frame the points are in
        self._previous: tuple[np.ndarray, np.ndarray] | None = None  # (T_raw, T_network)
        self._last_T_raw: np.ndarray | None = None
        self._lost = 0  # frames in a row without tracking
        self.needs_depth = False  # a new reference or a restart waits for a frame with depth
        self.states: Counter[str] = Counter()
        self.seconds = 0.0
        self.frames = 0

    def statistics(self) -> dict[str, object]:
        """Return frames per state and the mean cost per frame (ms)."""
        return {'states': dict(self.states),
                'ms_per_frame': 1000.0 * self.seconds / self.frames if self.frames else 0.0}

    def track(self, view: TrackingView | None, T_network: np.ndarray | None) -> TrackedFrame:
        """Return the frame's pose; ``T_network``: its network pose (4, 4), model units.

        ``T_network`` is None on a frame the geometry branch skipped (its ``view`` has no
        depth): the last pose is then the prior. The stream's first frame needs both.
        """
        start = time.perf_counter()
        if T_network is None:
            if self._last_T_raw is None or view is None or view.depth is not None:
                raise ValueError('CameraTracker.track: a frame without a network pose needs an '
                                 'earlier frame and a view without depth')
            result = self._track(view, self._last_T_raw)
        else:
            T_network = np.asarray(T_network, dtype=np.float64)
            result = self._track(view, self._prior(T_network))
            self._previous = (result.T_raw, T_network)
        self._last_T_raw = result.T_raw
        self.states[result.state] += 1
        self.frames += 1
        self.seconds += time.perf_counter() - start
        return result

    @property
    def lost(self) -> bool:
        """Return whether the last frame was not tracked (its pose is the prior)."""
        return self._lost > 0

    def moment(self) -> TrackerMoment:
        """Return the tracker as it is now, right after a frame (for a later ``absorb``)."""
        if self._last_T_raw is None:
            raise ValueError('CameraTracker.moment: no frame tracked yet')
        reference = None if self._reference is None else replace(self._reference)
        return TrackerMoment(self.frames, self._last_view, self._last_T_raw, reference,
                             self._lost > 0, self.needs_depth)

    def absorb(self, view: TrackingView, T_network: np.ndarray,
               moment: TrackerMoment | None = None) -> np.ndarray | None:
        """Take the network pose and depth of a frame tracked without them.

        ``view`` is that frame's view with its depth; ``moment`` the tracker right after it
        (``moment()``) when later frames were tracked since, None for the frame just tracked.
        A renewal due on the frame happens now, on it (the next frame is followed from it); a
        frame the tracker lost is bridged by the network's motion, as when its geometry came
        first (its pose is returned then, else None), and the next frame still needs depth.
        """
        if view.depth is None or self._last_T_raw is None:
            raise ValueError('CameraTracker.absorb: needs a tracked frame and its depth')
        start = time.perf_counter()
        moment = self.moment() if moment is None else moment
        latest = moment.frames == self.frames
        T_network = np.asarray(T_network, dtype=np.float64)
        T_raw, bridged = moment.T_raw, None
        if moment.lost:
            bridged = T_raw = self._prior(T_network)
            if latest:
                self._last_T_raw = T_raw
        elif moment.needs_depth and moment.reference is not None:
            since = self._last_view  # a frame tracked after it, if it is not moment.view
            self._renew(moment.reference, view, T_raw)
            self.needs_depth = False
            if since is not moment.view:
                self._follow_into(since)
        self._previous = (T_raw, T_network)
        self.seconds += time.perf_counter() - start
        return bridged

    def _follow_into(self, view: TrackingView) -> None:
        """Move a new reference's points into a later frame already tracked, at its pose.

        The reference is re-anchored so that the points give that frame the pose it was
        given (the track goes on from it without a jump); where too few points hold, it keeps
        its own pose.
        """
        reference = self._reference
        moved, survivors = self._follow(reference, view)
        solved = (self._solve(reference, view, moved, survivors, self._last_T_raw)
                  if survivors.sum() >= self.config.min_inliers else None)
        if solved is None:
            reference.points, reference.pixels = reference.points[survivors], moved[survivors]
        else:  # _solve kept the inliers
            reference.T_raw = self._last_T_raw @ solved[0]
        self._last_view = view

    def _track(self, view: TrackingView | None, prior: np.ndarray) -> TrackedFrame:
        if not self.config.enabled or view is None:
            return TrackedFrame(prior, 'predicted', 0)
        with_depth = view.depth is not None
        if with_depth:
            self.needs_depth = False
        reference = self._reference
        if reference is None:  # the stream's first frame: the world
            self._set_reference(view, prior, *self._lift(view))
            return TrackedFrame(prior, 'tracked', 0)
        moved, survivors = self._follow(reference, view)
        alive = int(survivors.sum())
        if alive >= self.config.min_inliers:
            solved = self._solve(reference, view, moved, survivors, prior)
            if solved is not None:
                T_current_reference, inliers = solved
                T_raw = reference.T_raw @ invert_transform(T_current_reference)
                self._last_view = view
                self._lost = 0
                if inliers < max(self.config.refresh_fraction * reference.count,
                                 self.config.min_inliers):
                    if with_depth:
                        self._renew(reference, view, T_raw)
                    else:
                        self.needs_depth = True
                return TrackedFrame(T_raw, 'tracked', inliers)
        self._lost += 1
        if not with_depth:  # nothing to restart on: the next frame brings depth
            self.needs_depth = True
            return TrackedFrame(prior, 'predicted', 0)
        had = len(reference.pixels)
        starved = had < self.config.min_inliers
        cut = (alive < self.config.cut_fraction * had
               and _sharpness(view.gray) >= self.config.blur_ratio * reference.sharpness)
        if starved or cut or self._lost >= self.config.max_lost_frames:
            points, pixels = self._lift(view)
            if len(points) >= self.config.min_inliers:  # texture here: start again on it
                self._set_reference(view, prior, points, pixels)
                return TrackedFrame(prior, 'predicted' if starved else 'reinitialised', 0)
        return TrackedFrame(prior, 'predicted', 0)

    def _prior(self, T_network: np.ndarray) -> np.ndarray:
        """Return the network's motion since the last frame it posed, applied to that pose."""
        if self._previous is None:
            return T_network
        T_previous, T_network_previous = self._previous
        return T_previous @ invert_transform(T_network_previous) @ T_network

    def _follow(self, reference: _Reference, view: TrackingView
                ) -> tuple[np.ndarray, np.ndarray]:
        """Move the reference's points into ``view`` by KLT: (P, 2) pixels, (P,) survived."""
        if not len(reference.pixels):
            return np.zeros((0, 2), np.float32), np.zeros(0, dtype=bool)
        start = reference.pixels.reshape(-1, 1, 2)
        last = self._last_view.gray
        moved, found, _ = cv2.calcOpticalFlowPyrLK(last, view.gray, start, None,
                                                   **self._lk)
        back, found_back, _ = cv2.calcOpticalFlowPyrLK(view.gray, last, moved, None,
                                                       **self._lk)
        moved = moved.reshape(-1, 2)
        error = np.linalg.norm(back.reshape(-1, 2) - reference.pixels, axis=1)
        survivors = ((found.ravel() == 1) & (found_back.ravel() == 1)
                     & (error <= self.config.forward_backward_px)
                     & _inside(moved, view.content_box)
                     & ~_in_boxes(moved, view.hand_boxes, self.config.hand_margin_px))
        return moved, survivors

    def _solve(self, reference: _Reference, view: TrackingView, moved: np.ndarray,
               survivors: np.ndarray, prior: np.ndarray) -> tuple[np.ndarray, int] | None:
        """Return (reference-to-frame transform, inliers) by PnP on the surviving points.

        None when it fails.
        """
        points = reference.points[survivors].astype(np.float64)
        pixels = moved[survivors].astype(np.float64)
        matrix = view.intrinsics.matrix()
        T_prior = invert_transform(prior) @ reference.T_raw  # reference -> current camera
        rvec, _ = cv2.Rodrigues(T_prior[:3, :3])
        tvec = T_prior[:3, 3].reshape(3, 1).copy()
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            points, pixels, matrix, None, rvec, tvec, useExtrinsicGuess=True,
            iterationsCount=100, reprojectionError=self.config.ransac_px, confidence=0.999,
            flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok or inliers is None or len(inliers) < self.config.min_inliers:
            return None
        inliers = inliers.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(points[inliers], pixels[inliers], matrix, None,
                                          rvec, tvec)
        rotation, _ = cv2.Rodrigues(rvec)
        T_current_reference = make_transform(rotation, tvec.ravel())
        step = np.degrees(np.arccos(np.clip(
            (np.trace(T_current_reference[:3, :3] @ T_prior[:3, :3].T) - 1.0) / 2.0, -1, 1)))
        if not np.isfinite(T_current_reference).all() or step > self.config.max_step_deg:
            return None
        keep = np.flatnonzero(survivors)[inliers]
        reference.points = reference.points[keep]
        reference.pixels = moved[keep]
        return T_current_reference, len(inliers)

    def _renew(self, reference: _Reference, view: TrackingView, T_raw: np.ndarray) -> None:
        """Make ``view`` (at ``T_raw``) the reference: the points held, then new corners."""
        T_new_old = invert_transform(T_raw) @ reference.T_raw
        kept = (reference.points.astype(np.float64) @ T_new_old[:3, :3].T
                + T_new_old[:3, 3]).astype(np.float32)
        points, pixels = self._lift(view, reference.pixels, self.config.max_corners - len(kept))
        kept /= _depth_agreement(kept, view.depth(), reference.pixels)
        self._set_reference(view, T_raw, np.concatenate([kept, points]),
                            np.concatenate([reference.pixels, pixels]))

    def _lift(self, view: TrackingView, taken: np.ndarray | tuple = (),
              count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return corners of ``view`` off the hands and ``taken`` pixels: points, pixels.

        (P, 3) camera points and (P, 2) pixels, at most ``count`` (``max_corners`` if None).
        """
        config = self.config
        count = config.max_corners if count is None else count
        if count <= 0:
            return np.zeros((0, 3), np.float32), np.zeros((0, 2), np.float32)
        mask = np.zeros(view.gray.shape, dtype=np.uint8)
        x0, y0, x1, y1 = view.content_box
        mask[y0:y1, x0:x1] = 255
        margin = config.hand_margin_px
        height, width = mask.shape
        for box in np.asarray(view.hand_boxes, dtype=np.float64).reshape(-1, 4):
            if not np.isfinite(box).all():
                continue
            bx0, by0 = (np.floor(box[:2]) - margin).astype(int).clip(0)
            bx1, by1 = (np.ceil(box[2:]) + margin + 1).astype(int)
            mask[by0:min(by1, height), bx0:min(bx1, width)] = 0
        for u, v in taken:
            cv2.circle(mask, (int(round(u)), int(round(v))),
                       int(np.ceil(config.min_corner_distance_px)), 0, -1)
        corners = cv2.goodFeaturesToTrack(view.gray, count, config.corner_quality,
                                          config.min_corner_distance_px, mask=mask)
        if corners is None:
            return np.zeros((0, 3), np.float32), np.zeros((0, 2), np.float32)
        pixels = corners.reshape(-1, 2).astype(np.float32)
        depth = _depth_at(view.depth(), pixels)
        good = np.isfinite(depth) & (depth > 0)
        pixels, depth = pixels[good], depth[good]
        intrinsics = view.intrinsics
        points = np.stack([(pixels[:, 0] - intrinsics.cx) / intrinsics.fx * depth,
                           (pixels[:, 1] - intrinsics.cy) / intrinsics.fy * depth,
                           depth], axis=1).astype(np.float32)
        return points, pixels

    def _set_reference(self, view: TrackingView, T_raw: np.ndarray, points: np.ndarray,
                       pixels: np.ndarray) -> None:
        """Make ``view`` the reference at pose ``T_raw``, with its lifted corners."""
        self._reference = _Reference(np.array(T_raw, dtype=np.float64), points, pixels,
                                     len(points), _sharpness(view.gray))
        self._last_view = view
        self._lost = 0


def _depth_agreement(points: np.ndarray, depth: np.ndarray, pixels: np.ndarray) -> float:
    """Return the median ratio of ``points``' depths to ``depth`` at their ``pixels`` (1: none).

    The points kept from the last reference are divided by it, so that they agree with the
    corners lifted from this frame's depth (the network's depth scale varies between frames).
    """
    measured = _depth_at(depth, pixels)
    good = np.isfinite(measured) & (measured > 0) & (points[:, 2] > 0)
    if not good.any():
        return 1.0
    return float(np.median(points[good, 2] / measured[good]))


def _depth_at(depth: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Return (P,) float64 values of the (H, W) ``depth`` at the nearest pixel to each (u, v)."""
    height, width = depth.shape
    rows = np.clip(np.round(pixels[:, 1]).astype(int), 0, height - 1)
    cols = np.clip(np.round(pixels[:, 0]).astype(int), 0, width - 1)
    return depth[rows, cols].astype(np.float64)


def _sharpness(gray: np.ndarray) -> float:
    """Return the variance of the image's Laplacian (low: blurred or textureless)."""
    return float(cv2.Laplacian(gray, cv2.CV_32F).var())


def _inside(pixels: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """Return (P,) bool: the pixels lie inside ``box`` (x0, y0, x1, y1; x1, y1 exclusive)."""
    x0, y0, x1, y1 = box
    return ((pixels[:, 0] >= x0) & (pixels[:, 0] <= x1 - 1)
            & (pixels[:, 1] >= y0) & (pixels[:, 1] <= y1 - 1))


def _in_boxes(pixels: np.ndarray, boxes: np.ndarray, margin: float) -> np.ndarray:
    """Return (P,) bool: the pixels lie in any of the boxes grown by ``margin``."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    if not len(boxes):
        return np.zeros(len(pixels), dtype=bool)
    x, y = pixels[:, 0:1], pixels[:, 1:2]
    inside = ((x >= boxes[:, 0] - margin) & (x <= boxes[:, 2] + margin)
              & (y >= boxes[:, 1] - margin) & (y <= boxes[:, 3] + margin))
    return inside.any(axis=1)
