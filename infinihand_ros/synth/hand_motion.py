"""Smooth reach/grasp motions of two hands in the scene's world frame (z up, table top known).

Each hand moves between keyframes a second or two apart. A keyframe is a reach to a point on the
table (grasp: fingers close on arrival), a hover in front of the head or a rest
low by the body (often out of view). Each keyframe also draws a finger gesture (``gestures``:
grasps of different sizes, pinches, pointing, open, fist, random fingers). A hover sometimes
crosses the body's midline, so the hands can occlude each other. Each hand continues its
forearm (``arms``: from the elbow to the wrist), turned by the wrist's angles drawn per keyframe
within a relaxed range (palm mostly down, fingers lifted or bent a little, swung sideways), so
hands are seen as a head-mounted camera sees them. Positions and orientations are
world-anchored, so hand motion and head motion are independent; between keyframes positions and
finger angles follow minimum-jerk profiles and orientations are slerped with the same profile.
Poses are MANO parameters of the built-in hand.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.mano.capsules import joint_radii
from infinihand_ros.synth import arms
from infinihand_ros.synth import gestures
from infinihand_ros.synth.scene import Scene
import numpy as np
from scipy.spatial.transform import Rotation
from scipy.spatial.transform import Slerp

#: Seconds between hand keyframes.
KEYFRAME_GAP_S: Final = (1.0, 2.2)
#: Probabilities of the keyframe kinds (reach to the table, hover in view, rest by the body).
KIND_PROBABILITIES: Final = {'grasp': 0.5, 'hover': 0.4, 'rest': 0.1}
#: Horizontal distance from the head to a reach target on the table (m).
REACH_M: Final = (0.1, 0.4)
#: Sideways distance from the head to a reach target, towards the hand's side (m).
GRASP_SIDE_M: Final = (0.05, 0.3)
#: Wrist height above the table top when grasping (m).
GRASP_HEIGHT_M: Final = (0.08, 0.14)
#: Hover point relative to the head: forward, sideways (per side), downwards (m).
HOVER_FORWARD_M: Final = (0.25, 0.4)
HOVER_SIDE_M: Final = (0.08, 0.25)
#: Probability that a hover crosses the midline (towards the other hand), and how far (m).
CROSS_PROBABILITY: Final = 0.1
CROSS_SIDE_M: Final = (0.0, 0.12)
HOVER_DOWN_M: Final = (0.2, 0.4)
#: Rest point relative to the head: sideways and downwards (m).
REST_SIDE_M: Final = 0.25
REST_DOWN_M: Final = 0.75
#: Wrist angles per keyframe kind (degrees, uniform ranges): supination (0 palm down, 90 palm
#: inwards), extension (fingers lifted towards the back of the hand) and sideways deviation.
WRIST_ANGLES_DEG: Final = {'grasp': ((-10.0, 50.0), (-5.0, 35.0), (-20.0, 20.0)),
                           'hover': ((-20.0, 50.0), (-25.0, 25.0), (-20.0, 20.0)),
                           'rest': ((0.0, 20.0), (-10.0, 10.0), (-10.0, 10.0))}
#: Random rotation of the hand around its wrist pose (degrees, 1 sigma per axis).
ORIENTATION_JITTER_DEG: Final = 8.0
#: Skin tones (RGB) to draw from; a per-sequence jitter is added.
SKIN_TONES: Final = ((233, 192, 160), (224, 172, 136), (198, 134, 96), (161, 102, 70),
                     (120, 76, 52), (245, 210, 185))
#: Standard deviation of the hand shape coefficients drawn per sequence.
BETA_SIGMA: Final = 0.8


@dataclass(frozen=True)
class HandTrack:
    """One hand's motion over a sequence, in the scene's world frame.

    Attributes:
        side: 0 left, 1 right.
        global_orient: (T, 3) axis-angle of the hand in the scene frame.
        hand_pose: (T, 15, 3) axis-angle articulation (MANO order, flat-hand relative).
        betas: (10,) shape, constant over the sequence.
        transl: (T, 3) MANO translation in the scene frame (m).
        radii: (21,) capsule radius per joint (m), OpenPose order.
        skin_rgb: skin colour.

    """

    side: int
    global_orient: np.ndarray
    hand_pose: np.ndarray
    betas: np.ndarray
    transl: np.ndarray
    radii: np.ndarray
    skin_rgb: tuple[int, int, int]


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile ``10 t^3 - 15 t^4 + 6 t^5`` on [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau ** 2)


def _hand_rotation(side: int, fingers: np.ndarray, palm_normal: np.ndarray) -> np.ndarray:
    """Rotation of a hand whose fingers point along ``fingers`` and palm faces ``palm_normal``."""
    fingers = fingers / np.linalg.norm(fingers)
    palm_normal = palm_normal - (palm_normal @ fingers) * fingers
    palm_normal /= np.linalg.norm(palm_normal)
    # Canonical right hand: x = -fingers, y = -palm normal, z = thumb = x cross y.
    x_axis = fingers if side == LEFT else -fingers
    y_axis = -palm_normal
    return np.stack([x_axis, y_axis, np.cross(x_axis, y_axis)], axis=1)


def _forearm_frame(wrist: np.ndarray, T_world_cam: np.ndarray, side: int,
                   style: arms.ArmStyle) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the unit vectors (3,) of a forearm: its axis (elbow to wrist), palm down and inwards.

    Palm down is the downward direction across the forearm; inwards is across both, towards the
    body's midline. An arm hanging straight down takes inwards as its palm-down direction.
    """
    _, _, elbow, _ = arms.arm_points(wrist, T_world_cam, side, style)
    axis = (wrist - elbow) / max(np.linalg.norm(wrist - elbow), 1e-6)
    _, left = arms.head_axes(T_world_cam)
    inwards = -left if side == LEFT else left
    reference = np.array([0.0, 0.0, -1.0])
    if np.linalg.norm(np.cross(reference, axis)) < 0.3:
        reference = inwards
    palm_down = reference - (reference @ axis) * axis
    palm_down /= np.linalg.norm(palm_down)
    across = np.cross(axis, palm_down)
    return axis, palm_down, across if across @ inwards >= 0 else -across


def _wrist_pose(side: int, forearm: tuple[np.ndarray, np.ndarray, np.ndarray],
                supination: float, extension: float, deviation: float) -> np.ndarray:
    """Return the rotation of a hand continuing its forearm at the wrist's angles (radians).

    ``supination`` turns the palm from facing down (0) to facing inwards (pi/2, thumb up);
    ``extension`` lifts the fingers towards the back of the hand (negative: flexion);
    ``deviation`` swings them sideways in the palm's plane.
    """
    axis, palm_down, inwards = forearm
    normal = np.cos(supination) * palm_down + np.sin(supination) * inwards
    fingers = np.cos(extension) * axis - np.sin(extension) * normal
    fingers = np.cos(deviation) * fingers + np.sin(deviation) * np.cross(normal, axis)
    return _hand_rotation(side, fingers, normal)


def _keyframe_target(rng: np.random.Generator, scene: Scene, side: int,
                     T_world_cam: np.ndarray, style: arms.ArmStyle
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw one keyframe: wrist position, hand rotation and gesture vector (21,)."""
    head = T_world_cam[:3, 3]
    forward, left = arms.head_axes(T_world_cam)
    side_dir = left if side == LEFT else -left
    kinds = list(KIND_PROBABILITIES)
    kind = kinds[rng.choice(len(kinds), p=list(KIND_PROBABILITIES.values()))]
    down = np.array([0.0, 0.0, -1.0])
    if kind == 'grasp':
        offset = forward * rng.uniform(*REACH_M) + side_dir * rng.uniform(*GRASP_SIDE_M)
        wrist = head + offset
        wrist[2] = scene.table_top_z + rng.uniform(*GRASP_HEIGHT_M)
        wrist[:2] = np.clip(wrist[:2], scene.table.center[:2] - scene.table.half_extents[:2],
                            scene.table.center[:2] + scene.table.half_extents[:2])
        gesture = gestures.draw_gesture(rng, gestures.draw_kind(rng, gestures.GRASP_KINDS))
    elif kind == 'hover':
        lateral = (-rng.uniform(*CROSS_SIDE_M) if rng.uniform() < CROSS_PROBABILITY
                   else rng.uniform(*HOVER_SIDE_M))
        wrist = (head + forward * rng.uniform(*HOVER_FORWARD_M)
                 + side_dir * lateral + down * rng.uniform(*HOVER_DOWN_M))
        gesture = gestures.draw_gesture(rng, gestures.draw_kind(rng, gestures.HOVER_KINDS))
    else:
        wrist = head + side_dir * REST_SIDE_M + down * REST_DOWN_M
        gesture = gestures.draw_gesture(rng, 'rest')
    wrist[2] = max(wrist[2], scene.table_top_z + GRASP_HEIGHT_M[0])
    supination, extension, deviation = (np.radians(rng.uniform(*span))
                                        for span in WRIST_ANGLES_DEG[kind])
    rotation = _wrist_pose(side, _forearm_frame(wrist, T_world_cam, side, style),
                           supination, extension, deviation)
    jitter = Rotation.from_rotvec(rng.normal(scale=np.radians(ORIENTATION_JITTER_DEG), size=3))
    return wrist, jitter.as_matrix() @ rotation, gesture.as_vector()


def _interpolate(times: np.ndarray, key_times: np.ndarray, key_positions: np.ndarray,
                 key_rotations: Rotation, key_gestures: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk interpolation of keyframes at ``times`` (positions, axis-angles, gestures)."""
    segment = np.clip(np.searchsorted(key_times, times, side='right') - 1, 0, len(key_times) - 2)
    tau = (times - key_times[segment]) / (key_times[segment + 1] - key_times[segment])
    weight = minimum_jerk(tau)
    positions = ((1.0 - weight)[:, None] * key_positions[segment]
                 + weight[:, None] * key_positions[segment + 1])
    gesture = ((1.0 - weight)[:, None] * key_gestures[segment]
               + weight[:, None] * key_gestures[segment + 1])
    slerp = Slerp(key_times, key_rotations)
    eased_times = key_times[segment] + weight * (key_times[segment + 1] - key_times[segment])
    return positions, slerp(eased_times).as_rotvec(), gesture


def make_hand_track(rng: np.random.Generator, scene: Scene, side: int,
                    T_world_cams: np.ndarray, fps: float, betas: np.ndarray,
                    skin_rgb: tuple[int, int, int], arm_style: arms.ArmStyle) -> HandTrack:
    """Draw one hand's motion for the camera trajectory ``T_world_cams`` (T, 4, 4).

    Args:
        rng: random generator (consumed deterministically).
        scene: the room (its table is the reach target).
        side: 0 left, 1 right.
        T_world_cams: camera-to-scene poses per frame (the person's head).
        fps: frame rate (Hz).
        betas: (10,) hand shape.
        skin_rgb: skin colour.
        arm_style: the person's arms (each hand continues its forearm).

    """
    num_frames = len(T_world_cams)
    duration = num_frames / fps
    gaps = rng.uniform(*KEYFRAME_GAP_S, size=int(duration / KEYFRAME_GAP_S[0]) + 3)
    key_times = np.concatenate([[0.0], np.cumsum(gaps)]) - rng.uniform(0.0, gaps[0])
    key_frames = np.clip(np.round(key_times * fps).astype(int), 0, num_frames - 1)
    targets = [_keyframe_target(rng, scene, side, T_world_cams[k], arm_style)
               for k in key_frames]
    times = np.arange(num_frames) / fps
    positions, orient, gesture = _interpolate(
        times, key_times, np.stack([t[0] for t in targets]),
        Rotation.from_matrix(np.stack([t[1] for t in targets])), np.stack([t[2] for t in targets]))
    radii = joint_radii(betas)
    return HandTrack(side=side, global_orient=orient,
                     hand_pose=gestures.gesture_hand_pose(gesture, side),
                     betas=betas, transl=positions, radii=radii, skin_rgb=skin_rgb)


def sample_hand_appearance(rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Draw a person's hand shape (10 betas, shared by both hands) and skin colour."""
    betas = np.clip(rng.normal(scale=BETA_SIGMA, size=NUM_BETAS), -2.0, 2.0)
    tone = np.array(SKIN_TONES[rng.integers(len(SKIN_TONES))], dtype=float)
    tone = np.clip(tone + rng.normal(scale=8.0, size=3), 0, 255)
    return betas, (int(tone[0]), int(tone[1]), int(tone[2]))
