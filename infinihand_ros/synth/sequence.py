"""Synthetic egocentric sequences with exact ground truth, frame by frame.

A ``SyntheticSequence`` draws a room, a body trajectory, intrinsics and two hands' motions from one
seed, computes every hand joint once (batched forward kinematics of the built-in hand), turns the
head (the camera) towards the hands in use and renders frames on demand. Ground truth uses the
project's conventions: the world frame is the first camera's (OpenCV optical), poses are
camera-to-world, joints are in OpenPose order, metres.

With ``distortion`` set (``'MODEL:c1,c2,...'``, as ``bag_to_dataset --distortion``), the camera
has that lens on the same drawn K: each frame is rendered pinhole on a larger canvas, warped into
the distorted image (``synth.lens``) before noise and JPEG, and the ground truth's pixels
(``joints_2d``, masks, boxes, depth) are the distorted image's; the intrinsics carry the lens.
The same seed draws the same scene, motion and K with or without a lens.
"""

from dataclasses import dataclass
from dataclasses import replace
from typing import Final, Iterator

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.distortion import parse_distortion
from infinihand_ros.core.distortion import project_points
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.core.raster import mask_box
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.synth import arms
from infinihand_ros.synth import camera_motion
from infinihand_ros.synth import hand_motion
from infinihand_ros.synth.lens import lens_warp
from infinihand_ros.synth.render import ArmGeometry
from infinihand_ros.synth.render import Exposure
from infinihand_ros.synth.render import HandGeometry
from infinihand_ros.synth.render import render_frame
from infinihand_ros.synth.render import RenderOptions
from infinihand_ros.synth.render import RenderOutput
from infinihand_ros.synth.scene import make_scene
from infinihand_ros.synth.sensor import degrade
import numpy as np
import torch

#: Stamp of frame 0 (2026-01-01T00:00:00Z), so bags carry plausible absolute times.
START_TIME_NS: Final = 1_767_225_600_000_000_000
HAND_CHOICES: Final = {'both': (LEFT, RIGHT), 'left': (LEFT,), 'right': (RIGHT,)}
#: The wrist and the four knuckles: their mean is where the head looks at a hand.
PALM_JOINTS: Final = (0, 5, 9, 13, 17)


@dataclass(frozen=True)
class SynthConfig:
    """Settings of a synthetic sequence (``config/synth.yaml``, section ``synth``).

    Attributes:
        fps: frame rate (Hz); the paper samples video at 10 FPS.
        width: image width (px).
        height: image height (px).
        hands: which hands appear: 'both', 'left' or 'right'.
        noise_sigma: image noise standard deviation (uint8 units).
        exposure_s: shutter time (s), centred on the frame's time: each image averages the
            camera's and the hands' motion over it (motion blur); 0: still images.
        min_visible_px: a hand with fewer visible pixels is marked not visible.
        jpeg_quality: JPEG compression of the rendered images (1-100, as a camera's); 0: none.
        distortion: the lens, ``'MODEL:c1,c2,...'`` (``core.distortion.parse_distortion``,
            e.g. ``'plumb_bob:-0.25,0.08,0,0,0'``); '' for a pinhole camera.

    """

    fps: float = 10.0
    width: int = 518
    height: int = 378
    hands: str = 'both'
    noise_sigma: float = 2.0
    exposure_s: float = 0.01
    min_visible_px: int = 40
    jpeg_quality: int = 90
    distortion: str = ''

    def __post_init__(self) -> None:
        if self.distortion:
            parse_distortion(self.distortion, 'synth.distortion')
        if not 0.5 <= self.fps <= 120.0:
            raise InputError(f'fps must be within [0.5, 120], got {self.fps}')
        if not (32 <= self.width <= 4096 and 32 <= self.height <= 4096):
            raise InputError(
                f'image size must be within 32..4096 px, got {self.width}x{self.height}')
        if self.hands not in HAND_CHOICES:
            raise InputError(f'hands must be one of {sorted(HAND_CHOICES)}, got {self.hands!r}')
        if not 0 <= self.jpeg_quality <= 100:
            raise InputError(f'jpeg_quality must be 0 (none) to 100, got {self.jpeg_quality}')
        if self.noise_sigma < 0 or self.min_visible_px < 1:
            raise InputError('noise_sigma must be >= 0 and min_visible_px >= 1, got '
                             f'{self.noise_sigma}, {self.min_visible_px}')
        if not 0.0 <= self.exposure_s <= 1.0 / self.fps:
            raise InputError(f'exposure_s must be within [0, 1 / fps = {1.0 / self.fps:g}] s, '
                             f'got {self.exposure_s}')


@dataclass(frozen=True)
class HandTruth:
    """Ground truth of one hand in one frame (present whether or not it is visible).

    Attributes:
        side: 0 left, 1 right.
        visible: at least ``min_visible_px`` pixels of the hand are visible.
        mano_cam: MANO parameters in the camera frame.
        mano_world: MANO parameters in the world (first camera) frame.
        joints_cam: (21, 3) joints in the camera frame (m).
        joints_world: (21, 3) joints in the world frame (m).
        joints_2d: (21, 2) projected joints (px); depth floored at 1 cm for points behind.
        mask: (H, W) bool visible pixels of this hand.
        box_xyxy: (4,) tight box of the mask (px, x1/y1 exclusive); zeros if not visible.

    """

    side: int
    visible: bool
    mano_cam: ManoParams
    mano_world: ManoParams
    joints_cam: np.ndarray
    joints_world: np.ndarray
    joints_2d: np.ndarray
    mask: np.ndarray
    box_xyxy: np.ndarray


@dataclass(frozen=True)
class SynthFrame:
    """One rendered frame and its ground truth.

    Attributes:
        index: 0-based frame index.
        timestamp_ns: frame stamp (ns).
        rgb: (H, W, 3) uint8 image.
        depth: (H, W) float32 depth along the optical axis (m), +inf where empty.
        intrinsics: the camera's intrinsics (with the lens distortion, when set).
        camera_pose: ``T_world_cam`` with the world frame = the first camera.
        hands: one ``HandTruth`` per generated side, left first.

    """

    index: int
    timestamp_ns: int
    rgb: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics
    camera_pose: CameraPose
    hands: tuple[HandTruth, ...]


class SyntheticSequence:
    """A deterministic synthetic sequence: everything but the images is computed up front."""

    def __init__(self, config: SynthConfig, seed: int, num_frames: int) -> None:
        """Draw the scene, motions and ground-truth joints of ``num_frames`` frames."""
        if num_frames < 1:
            raise InputError(f'frames must be >= 1, got {num_frames}')
        self.config = config
        self.seed = seed
        self.num_frames = num_frames
        rng = np.random.default_rng(seed)
        self.scene = make_scene(rng)
        motion = camera_motion.sample_camera_motion(rng, self.scene, num_frames, config.fps)
        #: The body's trajectory (before the head turns to the hands): hands reach from it, and
        #: the arms hang from it.
        self.T_scene_body = motion.T_world_cam
        self.intrinsics = Intrinsics.from_matrix(
            camera_motion.sample_intrinsics(rng, config.width, config.height),
            config.width, config.height)
        if config.distortion:
            model, coefficients = parse_distortion(config.distortion, 'synth.distortion')
            self.intrinsics = replace(self.intrinsics, distortion_model=model,
                                      distortion=coefficients)
        self._lens = lens_warp(self.intrinsics) if self.intrinsics.is_distorted else None
        betas, skin = hand_motion.sample_hand_appearance(rng)
        self.arm_style = arms.sample_arm_style(rng)
        self.tracks = tuple(
            hand_motion.make_hand_track(rng, self.scene, side, self.T_scene_body, config.fps,
                                        betas, skin, self.arm_style)
            for side in HAND_CHOICES[config.hands])
        self.joints_scene = tuple(self._forward(track) for track in self.tracks)
        #: The camera (the head, turned towards the hands in use).
        self.T_scene_cams = camera_motion.look_at_hands(
            rng, motion, [joints[:, PALM_JOINTS].mean(axis=1) for joints in self.joints_scene],
            config.fps)
        self.T_world_scene = geometry.invert_transform(self.T_scene_cams[0])
        self._options = RenderOptions(noise_sigma=config.noise_sigma,
                                      jpeg_quality=config.jpeg_quality)

    @staticmethod
    def _forward(track: hand_motion.HandTrack) -> np.ndarray:
        """Joints (T, 21, 3) of a track in the scene frame (built-in hand, float64)."""
        model = BuiltinHandModel(track.side).double()
        num = len(track.transl)
        with torch.no_grad():
            out = model(torch.as_tensor(track.global_orient), torch.as_tensor(track.hand_pose),
                        torch.as_tensor(np.tile(track.betas, (num, 1))),
                        torch.as_tensor(track.transl))
        return out.joints.numpy()

    def __len__(self) -> int:
        """Return the number of frames."""
        return self.num_frames

    def __iter__(self) -> Iterator[SynthFrame]:
        """Render the frames in order."""
        return (self.frame(i) for i in range(self.num_frames))

    def camera_pose(self, index: int) -> CameraPose:
        """``T_world_cam`` of frame ``index`` (world = first camera)."""
        return CameraPose.from_matrix(self.T_world_scene @ self.T_scene_cams[index])

    def frame(self, index: int) -> SynthFrame:
        """Render frame ``index`` and assemble its ground truth."""
        if not 0 <= index < self.num_frames:
            raise InputError(f'frame index {index} outside 0..{self.num_frames - 1}')
        T_scene_cam, T_scene_body = self.T_scene_cams[index], self.T_scene_body[index]
        style = self.arm_style
        geometries = [
            HandGeometry(side=t.side, joints_world=j[index], radii=t.radii, skin_rgb=t.skin_rgb,
                         arm=ArmGeometry(arms.arm_points(j[index][0], T_scene_body, t.side, style),
                                         style.radii_m, style.sleeve_rgb))
            for t, j in zip(self.tracks, self.joints_scene)]
        # Noise depends on (seed, index) only, so any frame renders the same in any order.
        noise_seed = int(np.random.SeedSequence([self.seed, index]).generate_state(1)[0])
        options = replace(self._options, noise_seed=noise_seed)
        if self._lens is None:
            out = render_frame(self.scene, self.intrinsics.matrix(), T_scene_cam,
                               self.config.width, self.config.height, geometries, options,
                               self._exposure(index))
        else:  # pinhole on the lens's canvas, warped, then the camera's noise and JPEG
            canvas = render_frame(self.scene, self._lens.canvas_K, T_scene_cam,
                                  *self._lens.canvas_size, geometries,
                                  replace(options, noise_sigma=0.0, jpeg_quality=0),
                                  self._exposure(index))
            rgb = degrade(self._lens.warp_rgb(canvas.rgb), options.noise_sigma,
                          options.noise_seed, options.jpeg_quality)
            out = RenderOutput(rgb,
                               self._lens.warp_depth(canvas.depth),
                               self._lens.warp_masks(canvas.hand_masks))
        pose = self.camera_pose(index)
        hands = tuple(
            self._hand_truth(track, joints[index], index, pose, out.hand_masks[track.side])
            for track, joints in zip(self.tracks, self.joints_scene))
        stamp = START_TIME_NS + int(round(index * 1e9 / self.config.fps))
        return SynthFrame(index=index, timestamp_ns=stamp, rgb=out.rgb, depth=out.depth,
                          intrinsics=self.intrinsics, camera_pose=pose, hands=hands)

    def _exposure(self, index: int) -> Exposure | None:
        """Return the camera poses and joints (scene frame) at frame ``index``'s shutter.

        It opens and closes a fraction of the way to the previous and to the next frame
        (extrapolated at the sequence's ends); None for still images.
        """
        if self.config.exposure_s <= 0.0:
            return None
        half = 0.5 * self.config.exposure_s * self.config.fps  # of a frame interval
        poses, joints = [], []
        for step in (-1, 1):
            other, fraction = index + step, half
            if not 0 <= other < self.num_frames:
                other, fraction = index - step, -half
            if not 0 <= other < self.num_frames:
                other, fraction = index, 0.0
            poses.append(geometry.interpolate_transform(self.T_scene_cams[index],
                                                        self.T_scene_cams[other], fraction))
            joints.append([j[index] + fraction * (j[other] - j[index])
                           for j in self.joints_scene])
        return Exposure(np.array(poses), np.array(joints))

    def _hand_truth(self, track: hand_motion.HandTrack, joints_scene: np.ndarray, index: int,
                    pose: CameraPose, mask: np.ndarray) -> HandTruth:
        """Ground truth of one hand in frame ``index`` from its scene-frame joints and mask."""
        mano_scene = ManoParams(track.global_orient[index], track.hand_pose[index], track.betas,
                                track.transl[index])
        T_world_scene = self.T_world_scene
        mano_world = transform_mano_params(mano_scene, T_world_scene[:3, :3], T_world_scene[:3, 3])
        T_cam_world = pose.inverse_matrix()
        mano_cam = transform_mano_params(mano_world, T_cam_world[:3, :3], T_cam_world[:3, 3])
        joints_world = geometry.transform_points(T_world_scene, joints_scene)
        joints_cam = geometry.transform_points(T_cam_world, joints_world)
        visible = int(mask.sum()) >= self.config.min_visible_px
        return HandTruth(side=track.side, visible=visible, mano_cam=mano_cam,
                         mano_world=mano_world, joints_cam=joints_cam, joints_world=joints_world,
                         joints_2d=self._project(joints_cam),
                         mask=mask, box_xyxy=mask_box(mask) if visible else np.zeros(4))

    def _project(self, points_cam: np.ndarray) -> np.ndarray:
        """Project camera-frame points (N, 3) through the lens to pixels (N, 2).

        Depth is floored at ``geometry.MIN_PROJECTION_DEPTH_M`` so points behind stay finite.
        """
        intrinsics = self.intrinsics
        if intrinsics.distortion_model is None:
            return geometry.project_points(points_cam, intrinsics.matrix())
        floored = np.array(points_cam, dtype=np.float64)
        floored[:, 2] = np.maximum(floored[:, 2], geometry.MIN_PROJECTION_DEPTH_M)
        return project_points(floored, intrinsics.matrix(), intrinsics.distortion_model,
                              intrinsics.distortion)

    def describe(self) -> dict:
        """Summary of the drawn sequence (for metadata files)."""
        fov_h, fov_w = self.intrinsics.fov()
        return {'seed': self.seed, 'frames': self.num_frames, 'fps': self.config.fps,
                'width': self.config.width, 'height': self.config.height,
                'hands': [SIDE_NAMES[t.side] for t in self.tracks],
                'fov_deg': {'h': float(np.degrees(fov_h)), 'w': float(np.degrees(fov_w))},
                'distortion_model': self.intrinsics.distortion_model,
                'distortion': list(self.intrinsics.distortion)}
