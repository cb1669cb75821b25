"""Head-mounted camera motion and intrinsics for synthetic egocentric sequences.

A person stands at one side of the scene's table at eye height, walks a little along it (and
towards or away from it) and looks at a gaze point that wanders over the near half of the table
top, with some extra head turn and roll. Every motion is a sum of a few low-frequency sinusoids, so
poses are smooth (no jumps). ``look_at_hands`` then turns the head towards the hands in use, as
people look at what their hands do (the arms hang from the body's trajectory). Poses are
camera-to-world ``T_world_cam`` (4, 4) in the scene's world frame (z up, floor z = 0) with the
OpenCV optical camera frame (x right, y down, z forward).
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.scene import Scene
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation
from scipy.special import expit

#: Default image size (width, height) in pixels.
DEFAULT_WIDTH: Final = 518
DEFAULT_HEIGHT: Final = 378
#: Horizontal field of view of the cameras (degrees): webcams to wide head-mounted cameras.
FOV_RANGE_DEG: Final = (55.0, 95.0)
#: Sinusoids summed per motion channel.
NUM_SINUSOIDS: Final = 3
#: Every sinusoid completes at least this many cycles over a sequence.
MIN_CYCLES: Final = 0.5
#: Shrink steps of the walking amplitude tried before giving up on clearance, and the factor.
MAX_SHRINK_STEPS: Final = 8
SHRINK_FACTOR: Final = 0.5
#: The rest position lies within this fraction of the table edge's half length from its middle.
REST_LATERAL_FRACTION: Final = 0.5
#: Motion channels, one sum of sinusoids each (walk along and towards the table, bob, gaze
#: along and across the table, head pitch, yaw and roll). Do not reorder: seeds depend on it.
WAVE_CHANNELS: Final = ('walk_lateral', 'walk_depth', 'bob', 'gaze_lateral', 'gaze_depth',
                        'pitch', 'yaw', 'roll')
#: World up axis (the scene's z).
WORLD_UP: Final = np.array([0.0, 0.0, 1.0])


#: Where the person stands: (table edge midpoint on the floor (3,), outward unit normal of that
#: edge (3,), half length of the edge, table extent across the edge), metres.
_Stand = tuple[np.ndarray, np.ndarray, float, float]


@dataclass(frozen=True)
class CameraMotionConfig:
    """Ranges of the head motion (metres, degrees, hertz).

    Attributes:
        eye_height_range_m: eye (camera) height above the floor (seated to standing).
        standoff_range_m: horizontal distance from the table edge to the eyes at rest.
        path_length_range_m: length of the camera path over the sequence (before limits).
        max_speed_mps: walking speed limit (shrinks the path of short sequences).
        max_lateral_m: largest excursion along the table edge from the rest position.
        max_depth_m: largest excursion towards or away from the table.
        bob_m: vertical head bob amplitude.
        frequency_range_hz: frequencies of the sinusoids.
        gaze_depth_range_m: distance from the near table edge to the rest gaze point.
        gaze_lateral_m: gaze excursion along the table edge.
        gaze_depth_m: gaze excursion across the table.
        head_turn_deg: extra yaw and pitch excursion of the head about the gaze direction.
        roll_deg: head roll excursion.
        clearance_m: smallest distance from the camera to walls, the table and boxes (3D).
        hand_gaze_share_range: how far the head turns from the table gaze towards the hands in
            use (0: not at all, 1: onto them), drawn per sequence.
        hand_gaze_lag_s: the head follows the hands smoothed over this (Gaussian sigma, s).
        table_gaze_weight: weight of the table gaze beside each hand in use (weight 1 each).
        hand_in_use_m: a hand is in use when its palm is at most this far below the eyes and
            ahead of them by at least the second value (m); the third softens both limits.

    """

    eye_height_range_m: tuple[float, float] = (1.05, 1.35)
    standoff_range_m: tuple[float, float] = (0.15, 0.35)
    path_length_range_m: tuple[float, float] = (0.4, 2.5)
    max_speed_mps: float = 0.6
    max_lateral_m: float = 0.9
    max_depth_m: float = 0.1
    bob_m: float = 0.02
    frequency_range_hz: tuple[float, float] = (0.03, 0.15)
    gaze_depth_range_m: tuple[float, float] = (0.05, 0.25)
    gaze_lateral_m: float = 0.35
    gaze_depth_m: float = 0.15
    head_turn_deg: float = 10.0
    roll_deg: float = 4.0
    clearance_m: float = 0.15
    hand_gaze_share_range: tuple[float, float] = (0.6, 0.9)
    hand_gaze_lag_s: float = 0.3
    table_gaze_weight: float = 0.15
    hand_in_use_m: tuple[float, float, float] = (0.6, 0.12, 0.04)

    def __post_init__(self) -> None:
        if self.standoff_range_m[0] <= self.max_depth_m:
            raise ConfigError(
                f'standoff_range_m={self.standoff_range_m} must start above max_depth_m='
                f'{self.max_depth_m} so that the eyes never pass over the table edge')
        if self.max_speed_mps <= 0 or self.frequency_range_hz[0] <= 0:
            raise ConfigError(f'max_speed_mps={self.max_speed_mps} and frequency_range_hz='
                              f'{self.frequency_range_hz} must be positive')


@dataclass(frozen=True)
class CameraMotion:
    """A sampled head trajectory.

    Attributes:
        T_world_cam: (T, 4, 4) camera-to-world poses.
        gaze_world: (T, 3) points on the table top the camera looks at (m); hands belong near
            them.

    """

    T_world_cam: np.ndarray
    gaze_world: np.ndarray


def sample_intrinsics(rng: np.random.Generator, width: int = DEFAULT_WIDTH,
                      height: int = DEFAULT_HEIGHT,
                      fov_range_deg: tuple[float, float] = FOV_RANGE_DEG) -> np.ndarray:
    """Draw pinhole intrinsics: random horizontal FoV, square pixels, centred principal point.

    Args:
        rng: random generator.
        width: image width (pixels).
        height: image height (pixels).
        fov_range_deg: range of the horizontal field of view (degrees, within (0, 180)).

    Returns:
        K (3, 3) float64 with ``cx = width / 2``, ``cy = height / 2``.

    Raises:
        InputError: on a non-positive size or a FoV range outside (0, 180).

    """
    if width <= 0 or height <= 0:
        raise InputError(f'image size must be positive, got {width}x{height}')
    if not 0.0 < fov_range_deg[0] <= fov_range_deg[1] < 180.0:
        raise InputError(f'fov_range_deg must be increasing within (0, 180), got {fov_range_deg}')
    fov = np.radians(rng.uniform(*fov_range_deg))
    focal = (width / 2.0) / np.tan(fov / 2.0)
    return np.array([[focal, 0.0, width / 2.0], [0.0, focal, height / 2.0], [0.0, 0.0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera-to-world rotations (T, 3, 3) of OpenCV cameras at ``eye`` (T, 3) facing ``target``.

    The image x axis stays horizontal (no roll) unless the view is vertical.
    """
    forward = target - eye
    forward /= np.linalg.norm(forward, axis=-1, keepdims=True)
    right = np.cross(forward, WORLD_UP)
    right /= np.linalg.norm(right, axis=-1, keepdims=True)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], axis=-1)


def _sinusoids(rng: np.random.Generator, times: np.ndarray, freq_range: tuple[float, float],
               channels: int) -> np.ndarray:
    """Return sums of sinusoids (T, channels), random frequencies, phases and weights, peak ~1."""
    duration = max(float(times[-1] - times[0]), 1e-6)
    low = max(freq_range[0], MIN_CYCLES / duration)
    high = max(freq_range[1], low)
    freqs = rng.uniform(low, high, (channels, NUM_SINUSOIDS))
    phases = rng.uniform(0.0, 2.0 * np.pi, (channels, NUM_SINUSOIDS))
    weights = rng.uniform(0.3, 1.0, (channels, NUM_SINUSOIDS))
    weights /= weights.sum(axis=1, keepdims=True)
    waves = np.sin(2.0 * np.pi * freqs[None] * times[:, None, None] + phases[None])
    return np.sum(weights[None] * waves, axis=-1)


def _stand_frame(rng: np.random.Generator, scene: Scene) -> _Stand:
    """Pick a table side: (edge midpoint (3,) on the floor, outward normal (3,), half edge, depth).

    ``depth`` is the table's extent across that edge.

    The lateral axis along the edge is ``cross(WORLD_UP, outward)``.
    """
    side = int(rng.integers(0, 4))
    axis = side // 2
    sign = 1.0 if side % 2 == 0 else -1.0
    outward = np.zeros(3)
    outward[axis] = sign
    half = scene.table.half_extents
    edge_mid = scene.table.center.copy()
    edge_mid[axis] += sign * half[axis]
    edge_mid[2] = 0.0
    return edge_mid, outward, float(half[1 - axis]), float(2.0 * half[axis])


def _clear(scene: Scene, positions: np.ndarray, margin_m: float) -> bool:
    """Return True when every camera position keeps ``margin_m`` from walls and obstacles."""
    inside = np.all(scene.room.contains(positions, -margin_m))
    hits = [np.any(box.contains(positions, margin_m)) for box in scene.obstacles]
    return bool(inside and not any(hits))


def _limit_walk(walk: np.ndarray, target_length: float, fps: float,
                config: CameraMotionConfig, half_edge: float) -> np.ndarray:
    """Scale a raw horizontal walk (T, 2) (along, towards the table) to the target path length.

    The scale is reduced where needed to respect the speed limit and the excursion limits.
    """
    steps = np.linalg.norm(np.diff(walk, axis=0), axis=1)
    length = float(steps.sum())
    if length <= 0.0:
        return walk
    scale = target_length / length
    scale = min(scale, config.max_speed_mps / fps / max(float(steps.max()), 1e-12))
    lateral = max(float(np.abs(walk[:, 0]).max()), 1e-12)
    depth = max(float(np.abs(walk[:, 1]).max()), 1e-12)
    scale = min(scale, min(config.max_lateral_m, half_edge) / lateral, config.max_depth_m / depth)
    return walk * scale


def sample_camera_motion(rng: np.random.Generator, scene: Scene, num_frames: int, fps: float,
                         config: CameraMotionConfig | None = None) -> CameraMotion:
    """Draw a smooth egocentric head trajectory around the scene's table.

    Args:
        rng: random generator (the only source of randomness).
        scene: the room (its table and obstacles).
        num_frames: number of poses T (>= 1).
        fps: frame rate (Hz, > 0).
        config: motion ranges; defaults to ``CameraMotionConfig()``.

    Returns:
        Poses and gaze points; the camera keeps ``config.clearance_m`` from walls and obstacles.

    Raises:
        InputError: on a bad frame count or rate.

    """
    config = config or CameraMotionConfig()
    if int(num_frames) < 1 or not fps > 0:
        raise InputError(f'num_frames must be >= 1 and fps > 0, got {num_frames} and {fps}')
    times = np.arange(int(num_frames)) / float(fps)
    stand = _stand_frame(rng, scene)
    rest_lateral = rng.uniform(-REST_LATERAL_FRACTION, REST_LATERAL_FRACTION) * stand[2]
    standoff = rng.uniform(*config.standoff_range_m)
    eye_height = rng.uniform(*config.eye_height_range_m)
    gaze_depth = rng.uniform(*config.gaze_depth_range_m)
    waves = _sinusoids(rng, times, config.frequency_range_hz, len(WAVE_CHANNELS))
    path_length = rng.uniform(*config.path_length_range_m)
    eyes = _eye_positions(scene, stand, np.array([rest_lateral, standoff, eye_height]), waves,
                          path_length, fps, config)
    gaze = _gaze_points(scene, stand, rest_lateral, gaze_depth, waves, config)
    turn = np.radians(np.stack([waves[:, WAVE_CHANNELS.index('pitch')] * config.head_turn_deg,
                                waves[:, WAVE_CHANNELS.index('yaw')] * config.head_turn_deg,
                                waves[:, WAVE_CHANNELS.index('roll')] * config.roll_deg], axis=1))
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, :3, :3] = look_at(eyes, gaze) @ Rotation.from_euler('xyz', turn).as_matrix()
    poses[:, :3, 3] = eyes
    return CameraMotion(poses, gaze)


def _eye_positions(scene: Scene, stand: _Stand, rest: np.ndarray, waves: np.ndarray,
                   path_length: float, fps: float, config: CameraMotionConfig) -> np.ndarray:
    """Eye positions (T, 3): rest (lateral, standoff, height) plus the limited walk and bob."""
    edge_mid, outward, half_edge, _ = stand
    lateral_axis = np.cross(WORLD_UP, outward)
    walk = _limit_walk(waves[:, :2], path_length, fps, config, half_edge)
    walk = np.concatenate([walk, waves[:, 2:3] * config.bob_m], axis=1)
    base = edge_mid + rest[0] * lateral_axis + rest[1] * outward
    base[2] = rest[2]
    for _ in range(MAX_SHRINK_STEPS):
        eyes = base + walk[:, :1] * lateral_axis - walk[:, 1:2] * outward + walk[:, 2:] * WORLD_UP
        if _clear(scene, eyes, config.clearance_m):
            return eyes
        walk = walk * SHRINK_FACTOR
    raise InputError('scene leaves no room for the camera; enlarge SceneConfig.table_clearance_m')


def _gaze_points(scene: Scene, stand: _Stand, rest_lateral: float, gaze_depth: float,
                 waves: np.ndarray, config: CameraMotionConfig) -> np.ndarray:
    """Gaze points (T, 3) wandering over the table top, clipped to it."""
    edge_mid, outward, half_edge, table_depth = stand
    lateral_axis = np.cross(WORLD_UP, outward)
    lateral = np.clip(rest_lateral + waves[:, WAVE_CHANNELS.index('gaze_lateral')]
                      * config.gaze_lateral_m, -half_edge, half_edge)
    depth = np.clip(gaze_depth + waves[:, WAVE_CHANNELS.index('gaze_depth')]
                    * config.gaze_depth_m, 0.0, table_depth)
    gaze = edge_mid + lateral[:, None] * lateral_axis - depth[:, None] * outward
    gaze[:, 2] = scene.table_top_z
    return gaze


def look_at_hands(rng: np.random.Generator, motion: CameraMotion, palms: list[np.ndarray],
                  fps: float, config: CameraMotionConfig | None = None) -> np.ndarray:
    """Turn the head of ``motion`` towards the hands in use: camera-to-world poses (T, 4, 4).

    The head turns from where its optical axis meets the table-top plane towards the palms
    (T, 3) of the hands in use (raised in front of the eyes; ``CameraMotionConfig.hand_in_use_m``):
    by the palms' offsets from that point, weighted smoothly (the point itself weighs
    ``table_gaze_weight``), smoothed over ``hand_gaze_lag_s`` and scaled by a per-sequence share.
    It keeps its roll and its eye positions; with no hand in use the poses are the body's.
    """
    config = config or CameraMotionConfig()
    body = motion.T_world_cam
    eyes, axis = body[:, :3, 3], body[:, :3, 2]
    reach = (motion.gaze_world[:, 2] - eyes[:, 2]) / np.minimum(axis[:, 2], -1e-3)
    table_point = eyes + axis * np.clip(reach, 0.2, 2.0)[:, None]
    forward = axis.copy()
    forward[:, 2] = 0.0
    forward /= np.maximum(np.linalg.norm(forward, axis=1, keepdims=True), 1e-9)
    below, ahead, soft = config.hand_in_use_m
    weights = [expit((palm[:, 2] - eyes[:, 2] + below) / soft)
               * expit((np.sum((palm - eyes) * forward, axis=1) - ahead) / soft)
               for palm in palms]
    total = config.table_gaze_weight + sum(weights, np.zeros(len(eyes)))
    offset = sum((w[:, None] * (p - table_point) for w, p in zip(weights, palms)),
                 np.zeros_like(eyes)) / total[:, None]
    offset = gaussian_filter1d(offset, config.hand_gaze_lag_s * fps, axis=0, mode='nearest')
    share = rng.uniform(*config.hand_gaze_share_range)
    roll = np.swapaxes(look_at(eyes, table_point), 1, 2) @ body[:, :3, :3]
    poses = body.copy()
    poses[:, :3, :3] = look_at(eyes, table_point + share * offset) @ roll
    return poses


def make_camera_trajectory(rng: np.random.Generator, scene: Scene, num_frames: int,
                           fps: float) -> np.ndarray:
    """Camera-to-world poses (T, 4, 4) of a smooth egocentric head trajectory.

    See ``sample_camera_motion`` (this returns its ``T_world_cam`` with the default config).
    """
    return sample_camera_motion(rng, scene, num_frames, fps).T_world_cam
