"""What the camera adds to a rendered image: motion blur over the exposure, noise and JPEG.

The renderer (``synth/render.py``) draws the frame at the middle of the exposure; ``expose``
then averages it along the paths the camera's and the hands' motion give each pixel while the
shutter is open (``Exposure``), and ``degrade`` adds Gaussian noise and JPEG compression last.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final
from typing import Protocol

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.validation import as_array
import numpy as np
from scipy.special import ndtri

#: Number of noise levels (one random byte per pixel and channel picks a Gaussian quantile).
NOISE_LEVELS: Final = 256
#: Motion blur: most samples of the exposure per image, the least motion (px) blurred, and the
#: block side (px) at whose centres the scene's motion is computed (then interpolated).
EXPOSURE_SAMPLES: Final = 8
MIN_BLUR_PX: Final = 0.5
FLOW_STEP: Final = 4


class FrameView(Protocol):
    """What ``expose`` reads of a frame in progress (the renderer's camera-frame buffers)."""

    rgb: np.ndarray  # (H, W, 3) uint8, blurred in place
    inv_depth: np.ndarray  # (H, W) float32 inverse z depth (1/m), 0 where empty
    k: np.ndarray  # (3, 3) intrinsics
    rot_cw: np.ndarray  # (3, 3) world-to-camera rotation
    t_cw: np.ndarray  # (3,) world-to-camera translation (m)


class BodyMotion(Protocol):
    """How each hand or arm part (a pixel owner) moves with its hand's joints."""

    hand_index: np.ndarray  # (N,) the hand each owner moves with
    joint_weights: np.ndarray  # (N, 21) weights of that hand's joints


@dataclass(frozen=True)
class Exposure:
    """Where the camera and the hands are when the shutter opens and when it closes.

    The image is the average over the exposure, the motion linear in between; the frame's own
    pose and joints (``render_frame``'s) are those of its middle, and its depth and masks.

    Attributes:
        T_world_cam: (2, 4, 4) camera-to-world poses at the opening and at the closing.
        joints_world: (2, H, 21, 3) joints of the H hands (``render_frame``'s order) at the
            opening and at the closing (world frame, m).

    """

    T_world_cam: np.ndarray
    joints_world: np.ndarray

    def __post_init__(self) -> None:
        as_array(self.T_world_cam, 'Exposure.T_world_cam', (2, 4, 4))
        joints = np.asarray(self.joints_world, np.float64)
        if joints.ndim != 4 or joints.shape[0] != 2 or joints.shape[2:] != (NUM_JOINTS, 3):
            raise InputError(f'Exposure.joints_world: expected shape (2, H, {NUM_JOINTS}, 3), '
                             f'got {joints.shape}')


def upsampled(coarse: np.ndarray, step: int, height: int, width: int) -> np.ndarray:
    """Bilinear upsampling of values at the centres of ``step``-pixel blocks to (height, width)."""
    blocks_y, blocks_x = coarse.shape[:2]
    return cv2.resize(coarse, (blocks_x * step, blocks_y * step),
                      interpolation=cv2.INTER_LINEAR)[:height, :width]


def _shifted_pixels(k: np.ndarray, u: np.ndarray, v: np.ndarray, depth: np.ndarray,
                    rot: np.ndarray, shift: np.ndarray,
                    travel: np.ndarray | None = None) -> np.ndarray:
    """Offsets (..., 2) from pixels (u, v) to where their points land in another camera.

    The points lie at ``depth`` along the pixels' rays in this camera; the other camera sees a
    point ``p`` at ``rot @ p + shift``, after it moved by ``travel`` ((..., 3), this camera's
    axes; None: static).
    """
    ray_x = (u - k[0, 2]) / k[0, 0]
    ray_y = (v - k[1, 2]) / k[1, 1]
    moved = np.stack([depth * (rot[i, 0] * ray_x + rot[i, 1] * ray_y + rot[i, 2]) + shift[i]
                      for i in range(3)], axis=-1)
    if travel is not None:
        moved += travel
    return project_points(moved, k) - np.stack(np.broadcast_arrays(u, v), axis=-1)


def expose(frame: FrameView, bodies: BodyMotion, owner: np.ndarray, moving: np.ndarray,
           hand_joints: Sequence[np.ndarray], exposure: Exposure) -> None:
    """Blur the image with the motion of the camera and the hands during the exposure.

    Each pixel's surface point moves (with its hand's joints, or with the scene) from where it
    is at the shutter's opening to where it is at its closing, and the camera moves too; the
    pixel averages the image along that path. Hands and arms also smear over the pixels they
    sweep: a pixel shows them for the share of the exposure they cover it (``_moving_layer``).

    Args:
        frame: the rendered frame (its ``rgb`` is blurred in place).
        bodies: how each hand or arm part moves with its hand's joints.
        owner: (H, W) int, the part each pixel shows.
        moving: (H, W) bool, the pixels that show a hand or arm part.
        hand_joints: (21, 3) world joints of each hand at the middle of the exposure (m).
        exposure: the camera's and the hands' poses at the opening and the closing.

    """
    height, width = owner.shape
    depth = np.full((height, width), 1e3, np.float32)  # empty pixels: far away
    np.divide(1.0, frame.inv_depth, out=depth, where=frame.inv_depth > 0)
    rot_wc, origin = frame.rot_cw.T, -frame.rot_cw.T @ frame.t_cw
    # The scene's paths vary smoothly: computed at the centre of every FLOW_STEP-pixel block and
    # interpolated; the hands' and arms' pixels exactly.
    step = FLOW_STEP
    blocks_y, blocks_x = -(-height // step), -(-width // step)
    centre_x = np.arange(blocks_x) * step + (step - 1) / 2.0
    centre_y = np.arange(blocks_y) * step + (step - 1) / 2.0
    coarse = np.empty((blocks_y, blocks_x, 4), np.float32)
    sampled = depth[np.minimum(centre_y.astype(int), height - 1)][
        :, np.minimum(centre_x.astype(int), width - 1)]
    rows, cols = np.nonzero(moving)
    exact = np.empty((rows.size, 4), np.float32)
    if rows.size:
        mid = np.array([np.asarray(joints, np.float64) for joints in hand_joints])
        ids = owner[rows, cols]
    for end, (T_world_cam, joints) in enumerate(zip(exposure.T_world_cam, exposure.joints_world)):
        pose = np.asarray(T_world_cam, np.float64)
        rot = pose[:3, :3].T @ rot_wc  # this end's camera <- the frame's camera
        shift = pose[:3, :3].T @ (origin - pose[:3, 3])
        coarse[..., 2 * end:2 * end + 2] = _shifted_pixels(
            frame.k, centre_x[None, :], centre_y[:, None], sampled, rot, shift)
        if rows.size:
            part = np.einsum('pj,pjc->pc', bodies.joint_weights,
                             (np.asarray(joints, np.float64) - mid)[bodies.hand_index])
            travel = part[ids] @ pose[:3, :3]  # world motion, in this camera
            exact[:, 2 * end:2 * end + 2] = _shifted_pixels(
                frame.k, cols, rows, depth[rows, cols], rot, shift, travel)
    offsets = upsampled(coarse, step, height, width)
    offsets[rows, cols] = exact
    path = offsets[..., 2:] - offsets[..., :2]
    longest = float(np.sqrt((path * path).sum(axis=-1).max()))
    if longest < MIN_BLUR_PX:
        return
    samples = int(min(EXPOSURE_SAMPLES, np.ceil(longest) + 1))
    pixels = np.stack(np.meshgrid(np.arange(width, dtype=np.float32),
                                  np.arange(height, dtype=np.float32)), axis=-1)
    layer = _moving_layer(moving, offsets, pixels) if rows.size else None
    grid = pixels - offsets[..., :2]
    total = np.zeros(frame.rgb.shape, np.float32)
    for fraction in np.linspace(0.0, 1.0, samples):
        where = cv2.scaleAdd(path, -fraction, grid)
        image = cv2.remap(frame.rgb, where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)
        cv2.accumulate(image, total)
        if layer is not None:
            y0, y1, x0, x1 = layer.region
            where = cv2.scaleAdd(layer.travel, -fraction, layer.start)
            alpha = cv2.remap(layer.cover, where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT)
            body = cv2.remap(frame.rgb, where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
            # Where the moving layer covers the pixel it shows the layer instead.
            total[y0:y1, x0:x1] += alpha[..., None] * (np.float32(body) - image[y0:y1, x0:x1])
    frame.rgb[:] = np.clip(total * np.float32(1.0 / samples) + 0.5, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class _Layer:
    """The hands and arms as a layer sweeping over the image during the exposure.

    Attributes:
        region: (y0, y1, x0, x1) pixels they can reach.
        start: (h, w, 2) where each pixel of the region looks into the layer at the opening.
        travel: (h, w, 2) how far that moves until the closing (px).
        cover: (H, W) float32, 1 on the layer's pixels in the frame's image.

    """

    region: tuple[int, int, int, int]
    start: np.ndarray
    travel: np.ndarray
    cover: np.ndarray


def _moving_layer(moving: np.ndarray, offsets: np.ndarray, pixels: np.ndarray) -> _Layer | None:
    """Build the layer of the moving pixels; None when none moves a pixel or more.

    Moving pixels follow their own paths, the others within reach the mean path of the moving
    pixels around them (so the layer smears over them along its motion).
    """
    rows, cols = np.nonzero(moving)
    travel = offsets[rows, cols, 2:] - offsets[rows, cols, :2]
    reach = int(np.ceil(float(np.sqrt((travel * travel).sum(axis=-1).max())) / 2.0))
    if reach < 1:
        return None
    height, width = moving.shape
    y0, y1 = max(int(rows.min()) - reach, 0), min(int(rows.max()) + reach + 1, height)
    x0, x1 = max(int(cols.min()) - reach, 0), min(int(cols.max()) + reach + 1, width)
    inside = moving[y0:y1, x0:x1]
    cover = moving.astype(np.float32)
    size = 2 * reach + 1
    own = offsets[y0:y1, x0:x1]
    weight = cv2.blur(cover[y0:y1, x0:x1], (size, size), borderType=cv2.BORDER_CONSTANT)
    mean = cv2.blur(own * cover[y0:y1, x0:x1, None], (size, size),
                    borderType=cv2.BORDER_CONSTANT)
    mean /= np.maximum(weight, np.float32(1e-6))[..., None]
    carried = (~inside & (weight > 0.5 / size ** 2))[..., None]  # a moving pixel within reach
    paths = np.where(carried, mean, own)
    return _Layer((y0, y1, x0, x1), pixels[y0:y1, x0:x1] - paths[..., :2],
                  paths[..., 2:] - paths[..., :2], cover)


def degrade(rgb: np.ndarray, noise_sigma: float, noise_seed: int,
            jpeg_quality: int) -> np.ndarray:
    """Apply Gaussian noise (``noise_sigma`` > 0, uint8 units) and JPEG (quality > 0) to RGB."""
    if noise_sigma > 0:
        # Gaussian noise by inverse-CDF lookup of random bytes (256 quantiles, rounded to
        # integers), several times faster than drawing normal floats.
        rng = np.random.default_rng(noise_seed)
        quantiles = ndtri((np.arange(NOISE_LEVELS) + 0.5) / NOISE_LEVELS)
        table = np.round(quantiles * noise_sigma).astype(np.int16)
        noise_bytes = np.frombuffer(rng.bytes(rgb.size), np.uint8).reshape(rgb.shape)
        rgb = cv2.add(rgb, cv2.LUT(noise_bytes, table), dtype=cv2.CV_8U)
    if jpeg_quality > 0:
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        _, encoded = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        rgb = cv2.cvtColor(cv2.imdecode(encoded, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return rgb
