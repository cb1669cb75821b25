"""Synthetic BA problems with known ground truth (shared by the BA tests)."""

from dataclasses import dataclass

from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.problem import BAProblem
from infinihand_ros.core import geometry
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np
from scipy.spatial.transform import Rotation

WIDTH, HEIGHT = 518, 378
K = np.array([[400.0, 0.0, 259.0], [0.0, 400.0, 189.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class SyntheticBA:
    """A BA problem and the ground truth it was drawn from."""

    problem: BAProblem
    T_world_cam: np.ndarray  # (F, 4, 4) true poses
    inv_depth: np.ndarray  # (P,) true inverse depths


def true_poses(rng: np.random.Generator, num_frames: int) -> np.ndarray:
    """Return (F, 4, 4) camera-to-world poses walking sideways and turning slowly."""
    angles = np.cumsum(rng.normal(0.0, 0.02, (num_frames, 3)), axis=0)
    angles -= angles[0]
    positions = np.cumsum(np.c_[np.full(num_frames, 0.08), rng.normal(0, 0.02, (num_frames, 2))],
                          axis=0)
    positions -= positions[0]
    return geometry.make_transform(Rotation.from_rotvec(angles).as_matrix(), positions)


def make_problem(rng: np.random.Generator, num_frames: int = 6, num_tracks: int = 150,
                 pixel_noise: float = 0.5, pose_noise: float = 0.02,
                 depth_prior_sigma: float = 0.05,
                 with_depth_prior: bool = True, num_fixed: int = 1,
                 with_pose_prior: bool = False,
                 lens: tuple[float, float] = (0.0, 0.0)) -> SyntheticBA:
    """Draw a scene 2-6 m in front of the cameras and a BA problem with perturbed poses.

    Observations carry Gaussian pixel noise; the initial poses (except the fixed ones) get
    ``pose_noise`` rad / m of noise; initial inverse depths are 10 % off; the depth prior (when
    given) is the truth with ``depth_prior_sigma`` relative noise. The pixels are seen through
    the true ``lens`` (log focal scale of ``K``, radial k1; ``ba.costs``); the problem's
    intrinsics are the plain ``K``.
    """
    poses = true_poses(rng, num_frames)
    host = rng.integers(0, num_frames, num_tracks)
    normal = (rng.uniform([20, 20], [WIDTH - 20, HEIGHT - 20], (num_tracks, 2))
              - K[:2, 2]) / np.diag(K)[:2]
    host_xy = _through_lens(normal, lens)
    depth = rng.uniform(2.0, 6.0, num_tracks)
    rays = np.c_[normal, np.ones(num_tracks)]
    points_world = geometry.transform_points(poses[host], (rays * depth[:, None])[:, None])[:, 0]
    points_cam = geometry.transform_points(geometry.invert_transform(poses)[:, None],
                                           points_world[None, :, None])[..., 0, :]  # (F, P, 3)
    pixels = _through_lens(points_cam[..., :2] / points_cam[..., 2:], lens)
    visible = ((points_cam[..., 2] > 0.1) & (pixels[..., 0] > 0) & (pixels[..., 0] < WIDTH)
               & (pixels[..., 1] > 0) & (pixels[..., 1] < HEIGHT))
    visible[host, np.arange(num_tracks)] = False
    obs_frame, obs_track = np.nonzero(visible)
    obs_xy = pixels[obs_frame, obs_track] + rng.normal(0.0, pixel_noise, (len(obs_track), 2))
    fixed = np.arange(num_frames) < num_fixed
    noisy = poses.copy()
    noise = rng.normal(0.0, pose_noise, (num_frames, 6))
    noisy[:, :3, :3] = Rotation.from_rotvec(noise[:, 3:]).as_matrix() @ poses[:, :3, :3]
    noisy[:, :3, 3] += noise[:, :3]
    noisy[fixed] = poses[fixed]
    prior = 1.0 / (depth * (1.0 + rng.normal(0.0, depth_prior_sigma, num_tracks)))
    pairs = np.c_[np.arange(num_frames - 1), np.arange(1, num_frames)] if with_pose_prior \
        else np.zeros((0, 2), dtype=int)
    inv_noisy = geometry.invert_transform(noisy)
    problem = BAProblem(
        T_world_cam=noisy, intrinsics=np.tile(K, (num_frames, 1, 1)), fixed=fixed, host=host,
        host_xy=host_xy, inv_depth=1.0 / (depth * rng.uniform(0.9, 1.1, num_tracks)),
        prior_inv_depth=prior if with_depth_prior else np.full(num_tracks, np.nan),
        prior_sigma=depth_prior_sigma * prior, obs_track=obs_track, obs_frame=obs_frame,
        obs_xy=obs_xy, obs_weight=np.ones(len(obs_track)), prior_pairs=pairs,
        prior_T_rel=inv_noisy[pairs[:, 0]] @ noisy[pairs[:, 1]])
    return SyntheticBA(problem, poses, 1.0 / depth)


def _through_lens(normal: np.ndarray, lens: tuple[float, float]) -> np.ndarray:
    """Return the pixels (..., 2) of normalised points (..., 2) seen through ``lens`` and K."""
    log_focal, k1 = lens
    radial = 1.0 + k1 * np.sum(normal**2, axis=-1, keepdims=True)
    return normal * radial * np.diag(K)[:2] * np.exp(log_focal) + K[:2, 2]


def synth_keyframe(frame: SynthFrame, T_world_cam: np.ndarray | None = None) -> KeyframeInput:
    """Return a BA keyframe from a synthetic frame (true depth; true pose unless given)."""
    hands = np.zeros(frame.depth.shape, dtype=bool)
    for hand in frame.hands:
        hands |= hand.mask
    pose = frame.camera_pose.matrix() if T_world_cam is None else T_world_cam
    return KeyframeInput(frame.index, frame.timestamp_ns, frame.rgb, frame.depth, pose,
                         frame.intrinsics, hands)
