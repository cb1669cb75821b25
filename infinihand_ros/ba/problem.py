"""Plain-data bundle-adjustment problem and result (keyframe poses + one inverse depth per track).

A track is hosted by one keyframe: its 3D point is the host pixel's ray at the track's inverse
depth, ``X_host = K_host^-1 [u, v, 1] / rho``. Observations are the track's pixels in the other
keyframes. Poses are camera-to-world (``T_world_cam``), 4x4, metres.
"""

from dataclasses import dataclass
from dataclasses import field
from dataclasses import replace

from infinihand_ros.core.errors import InputError
import numpy as np


@dataclass(frozen=True)
class BAProblem:
    """One BA call's variables, measurements and gauge.

    Attributes:
        T_world_cam: (F, 4, 4) initial camera-to-world poses of the keyframes, time order.
        intrinsics: (F, 3, 3) pinhole K per keyframe (px).
        fixed: (F,) bool, poses held constant (the gauge).
        host: (P,) int, host keyframe of each track.
        host_xy: (P, 2) the track's pixel in its host keyframe (px).
        inv_depth: (P,) initial inverse depth along the host ray (1/m, > 0).
        prior_inv_depth: (P,) depth-prior inverse depth (1/m); NaN where there is no prior.
        prior_sigma: (P,) sigma of that prior (1/m); ignored where the prior is NaN.
        obs_track: (M,) int, track of each observation.
        obs_frame: (M,) int, keyframe of each observation (never the track's host).
        obs_xy: (M, 2) observed pixel (px).
        obs_weight: (M,) confidence weight of each observation (>= 0).
        prior_pairs: (R, 2) int keyframe pairs (i, j) with a relative-pose prior.
        prior_T_rel: (R, 4, 4) measured ``T_cam_i_cam_j`` of each pair.
        lens_sigma: (2,) prior sigmas of the shared lens's log focal scale and radial k1
            around ``lens``; 0 holds that lens unknown fixed.
        lens: (2,) the shared lens to start from and centre its prior on (log focal scale of
            ``intrinsics``, radial k1; ``ba.costs``); zeros: the plain pinhole ``intrinsics``.

    """

    T_world_cam: np.ndarray
    intrinsics: np.ndarray
    fixed: np.ndarray
    host: np.ndarray
    host_xy: np.ndarray
    inv_depth: np.ndarray
    prior_inv_depth: np.ndarray
    prior_sigma: np.ndarray
    obs_track: np.ndarray
    obs_frame: np.ndarray
    obs_xy: np.ndarray
    obs_weight: np.ndarray
    prior_pairs: np.ndarray
    prior_T_rel: np.ndarray
    lens_sigma: np.ndarray = field(default_factory=lambda: np.zeros(2))
    lens: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        num_frames = len(self.T_world_cam)
        num_tracks = len(self.host)
        num_obs = len(self.obs_track)
        shapes = {
            'T_world_cam': (self.T_world_cam, (num_frames, 4, 4)),
            'intrinsics': (self.intrinsics, (num_frames, 3, 3)),
            'fixed': (self.fixed, (num_frames,)),
            'host_xy': (self.host_xy, (num_tracks, 2)),
            'inv_depth': (self.inv_depth, (num_tracks,)),
            'prior_inv_depth': (self.prior_inv_depth, (num_tracks,)),
            'prior_sigma': (self.prior_sigma, (num_tracks,)),
            'obs_frame': (self.obs_frame, (num_obs,)),
            'obs_xy': (self.obs_xy, (num_obs, 2)),
            'obs_weight': (self.obs_weight, (num_obs,)),
            'prior_T_rel': (self.prior_T_rel, (len(self.prior_pairs), 4, 4)),
            'lens_sigma': (self.lens_sigma, (2,)),
            'lens': (self.lens, (2,)),
        }
        for name, (array, shape) in shapes.items():
            if np.shape(array) != shape:
                raise InputError(f'BA problem: {name} has shape {np.shape(array)}, expected '
                                 f'{shape} for {num_frames} keyframes, {num_tracks} tracks and '
                                 f'{num_obs} observations')
        self._check_indices(num_frames, num_tracks)
        if np.any(~(self.inv_depth > 0)):
            raise InputError('BA problem: initial inverse depths must be positive and finite')
        if not np.all(np.isfinite(self.lens_sigma) & (np.asarray(self.lens_sigma) >= 0)):
            raise InputError(f'BA problem: lens_sigma must be finite and >= 0, got '
                             f'{self.lens_sigma}')
        if not np.any(self.fixed):
            raise InputError('BA problem: no fixed pose; fix at least one keyframe (the gauge)')

    def _check_indices(self, num_frames: int, num_tracks: int) -> None:
        """Raise InputError for an index outside its range or an observation in its host."""
        for name, index, limit in (('host', self.host, num_frames),
                                   ('obs_track', self.obs_track, num_tracks),
                                   ('obs_frame', self.obs_frame, num_frames),
                                   ('prior_pairs', self.prior_pairs, num_frames)):
            if np.size(index) and (np.min(index) < 0 or np.max(index) >= limit):
                raise InputError(f'BA problem: {name} holds indices outside 0..{limit - 1}')
        if np.any(self.host[self.obs_track] == self.obs_frame):
            raise InputError('BA problem: an observation lies in its own host keyframe; the '
                             'host pixel is given by host_xy')

    @property
    def num_frames(self) -> int:
        """Return the number of keyframes F."""
        return len(self.T_world_cam)

    def tracks(self, keep: np.ndarray) -> 'BAProblem':
        """Return the problem over the tracks where ``keep`` (P,) is True, with their views."""
        keep = np.asarray(keep, dtype=bool)
        new_id = np.full(len(keep), -1)
        new_id[keep] = np.arange(np.count_nonzero(keep))
        observed = keep[self.obs_track]
        return replace(self, host=self.host[keep], host_xy=self.host_xy[keep],
                       inv_depth=self.inv_depth[keep],
                       prior_inv_depth=self.prior_inv_depth[keep],
                       prior_sigma=self.prior_sigma[keep],
                       obs_track=new_id[self.obs_track[observed]],
                       obs_frame=self.obs_frame[observed], obs_xy=self.obs_xy[observed],
                       obs_weight=self.obs_weight[observed])

    @property
    def lens_free(self) -> np.ndarray:
        """Return (2,) bool: which lens unknowns (log focal scale, k1) are refined."""
        return np.asarray(self.lens_sigma) > 0

    @property
    def has_depth_prior(self) -> bool:
        """Return whether any track carries a depth prior."""
        return bool(np.any(np.isfinite(self.prior_inv_depth)))


@dataclass(frozen=True)
class BAResult:
    """Outcome of one BA call.

    Attributes:
        T_world_cam: (F, 4, 4) refined camera-to-world poses (fixed ones unchanged).
        inv_depth: (P,) refined inverse depths (1/m).
        inliers: (M,) bool, observations kept by the outlier gate.
        initial_cost: cost before the first iteration (robust, with the priors).
        final_cost: plain least-squares cost over the inliers at the end.
        iterations: LM iterations run (IRLS and plain together).
        lens: (2,) refined log focal scale and radial k1 (0 where held).

    """

    T_world_cam: np.ndarray
    inv_depth: np.ndarray
    inliers: np.ndarray
    initial_cost: float
    final_cost: float
    iterations: int
    lens: np.ndarray = field(default_factory=lambda: np.zeros(2))
