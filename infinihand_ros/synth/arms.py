"""Arms for the synthetic hands: from each wrist to the person's shoulder, below the camera.

The camera is the person's eyes; each shoulder sits below and a little behind them, to the side
of its hand (scene frame: z up). The elbow follows from the upper arm's and forearm's lengths (a
two-link arm reaching from the shoulder to the wrist), bent down, outwards and back, as elbows
hang; a wrist out of reach straightens the arm along the shoulder-wrist line. A sleeve covers the
forearm from its hem to the elbow, and the whole upper arm.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.synth import textures
import numpy as np

#: Shoulder relative to the eyes: down, sideways (towards its hand's side) and back (m).
SHOULDER_OFFSET_M: Final = (0.24, 0.19, 0.08)
#: Upper arm and forearm lengths of an average adult (m); scaled per person.
ARM_LENGTHS_M: Final = (0.29, 0.26)
#: Per-person scale range of the arm lengths and radii.
ARM_SCALE_RANGE: Final = (0.9, 1.1)
#: Radii (m) of the bare forearm, the sleeved forearm and the upper arm.
ARM_RADII_M: Final = (0.027, 0.036, 0.045)
#: Fraction of the forearm from the wrist to the sleeve's hem (short sleeves end at the elbow).
HEM_FRACTION_RANGE: Final = (0.15, 0.9)
#: Elbow bend direction: weights of down, outwards and back.
ELBOW_HINT: Final = (1.0, 0.6, 0.3)
#: Sleeve colours are muted: largest HSV saturation.
SLEEVE_SATURATION_MAX: Final = 0.35


@dataclass(frozen=True)
class ArmStyle:
    """A person's arms (both the same).

    Attributes:
        lengths_m: upper arm and forearm lengths (m).
        radii_m: (3,) radius of the bare forearm, the sleeved forearm and the upper arm (m).
        hem_fraction: where the sleeve starts, as a fraction of the forearm from the wrist.
        sleeve_rgb: sleeve colour (R, G, B) in 0-255.

    """

    lengths_m: tuple[float, float]
    radii_m: np.ndarray
    hem_fraction: float
    sleeve_rgb: tuple[int, int, int]


def sample_arm_style(rng: np.random.Generator) -> ArmStyle:
    """Draw a person's arm lengths, thickness, sleeve length and sleeve colour."""
    scale = rng.uniform(*ARM_SCALE_RANGE)
    colour = textures.random_colour(rng, saturation_max=SLEEVE_SATURATION_MAX)
    return ArmStyle(lengths_m=(ARM_LENGTHS_M[0] * scale, ARM_LENGTHS_M[1] * scale),
                    radii_m=np.asarray(ARM_RADII_M) * scale,
                    hem_fraction=float(rng.uniform(*HEM_FRACTION_RANGE)),
                    sleeve_rgb=(int(colour[0]), int(colour[1]), int(colour[2])))


def head_axes(T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal forward and left unit vectors (3,) of a camera-to-world pose (world z up)."""
    forward = T_world_cam[:3, 2].copy()
    forward[2] = 0.0
    norm = np.linalg.norm(forward)
    forward = forward / norm if norm > 1e-6 else np.array([1.0, 0.0, 0.0])
    return forward, np.cross([0.0, 0.0, 1.0], forward)


def arm_points(wrist: np.ndarray, T_world_cam: np.ndarray, side: int,
               style: ArmStyle) -> np.ndarray:
    """Return the wrist, sleeve hem, elbow and shoulder (4, 3) of one arm (world frame, m).

    Args:
        wrist: (3,) wrist joint of the hand (world frame, z up).
        T_world_cam: (4, 4) camera-to-world pose of the person's eyes.
        side: 0 left, 1 right.
        style: the person's arms.

    """
    forward, left = head_axes(T_world_cam)
    outwards = left if side == LEFT else -left
    down = np.array([0.0, 0.0, -1.0])
    drop, across, back = SHOULDER_OFFSET_M
    shoulder = T_world_cam[:3, 3] + down * drop + outwards * across - forward * back
    upper, fore = style.lengths_m
    reach = wrist - shoulder
    distance = max(float(np.linalg.norm(reach)), 1e-6)
    axis = reach / distance
    if distance >= upper + fore:
        elbow = shoulder + axis * (distance * upper / (upper + fore))
    else:
        distance = max(distance, abs(upper - fore))
        along = (upper ** 2 - fore ** 2 + distance ** 2) / (2.0 * distance)
        height = np.sqrt(max(upper ** 2 - along ** 2, 0.0))
        hint = ELBOW_HINT[0] * down + ELBOW_HINT[1] * outwards - ELBOW_HINT[2] * forward
        bend = hint - (hint @ axis) * axis
        bend_norm = np.linalg.norm(bend)
        bend = bend / bend_norm if bend_norm > 1e-6 else np.zeros(3)
        elbow = shoulder + along * axis + height * bend
    hem = wrist + style.hem_fraction * (elbow - wrist)
    return np.stack([wrist, hem, elbow, shoulder])
