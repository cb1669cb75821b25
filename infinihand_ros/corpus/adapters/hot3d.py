"""Adapter of HOT3D-Clips (Aria / Quest 3 headsets: moving fisheye camera, MANO hands).

Layout and conventions, from ``hot3d/clips/README.md`` and ``clip_util.py`` / ``vis_clips.py``
(facebookresearch/hot3d) and ``dataset.py``, ``camera.py``, ``camera_distortion.py`` and
``hand_models/mano_hand_model.py`` (facebookresearch/hand_tracking_toolkit)::

    ROOT/.../clip-<ID>.tar (or the same members extracted into a folder clip-<ID>/)
      <FRAME>.image_<STREAM>.jpg  FRAME = %06d; STREAM 214-1 (Aria RGB), 1201-1 / 1201-2 (grey)
      <FRAME>.cameras.json        <STREAM>: calibration {image_width, image_height,
                                  projection_model_type, projection_params}, T_world_from_camera
                                  {translation_xyz, quaternion_wxyz}
      <FRAME>.hands.json          left / right (either may be missing): mano_pose {thetas (15),
                                  wrist_xform (6)}, umetrack_pose {...}
      <FRAME>.info.json           image_timestamps_ns {<STREAM>: ns}, device
      __hand_shapes.json__        mano: (10,) betas shared by both hands; umetrack: user profile

Cameras follow OpenCV (x right, y down, z forward; the toolkit's ``camera.py``), so
``T_world_from_camera`` is already our camera-to-world pose; it is re-based to the first frame
(Stage II). ``CameraModelType.FISHEYE624`` parameters are ``fx, fy, cx, cy`` then 6 radial, 2
tangential and 4 thin-prism coefficients of the toolkit's arctan (equidistant) projection; frames
are warped on load to a pinhole camera with the same ``fx, fy, cx, cy`` and size (what the
toolkit's ``convert_to_pinhole_camera`` + ``warp_image`` do), so ``K`` holds. Camera-frame
joints are unchanged by that warp. The RGB stream 214-1 is used where present (Aria), else the
grey 1201-1 (Quest 3, replicated to three channels).

``mano_pose`` is for smplx's MANO layer with ``use_pca=True``, 15 components and the default
``flat_hand_mean=False``: full pose ``thetas @ hands_components[:15] + hands_mean`` (relative to
the flat hand, ours); ``wrist_xform`` is ``global_orient`` and ``transl`` in the world. Left
hands use MANO_LEFT with the left-shapedirs fix the toolkit applies (no mirroring). Joints need
the real MANO files (the user's): as for ARCTIC the adapter poses them, keeps the camera-frame
MANO when the corpus uses real MANO and otherwise leaves MANO to be fitted. Our tip vertices
(744, 320, 443, 554, 671) are the toolkit's. A hand-frame without ``mano_pose`` (the toolkit
notes MANO registration can fail) or without that side counts as no hand. Clips without
``hands.json`` (test splits) are skipped.

Not supported: UmeTrack poses (its forward kinematics needs the serialized user profile), the
full VRS-based HOT3D recordings, the grey Aria streams and the second Quest 3 stream, other
projection models than FISHEYE624 / PinholePlane. Without ``image_timestamps_ns`` stamps
assume 30 Hz (150 frames = 5 s, README).
"""

from collections.abc import Iterator
from dataclasses import dataclass
import json
import logging
from pathlib import Path
import tarfile
from typing import Final

import cv2
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.corpus.adapters.frames import empty_hands
from infinihand_ros.corpus.adapters.frames import rebase_to_first
from infinihand_ros.corpus.adapters.frames import stamps_from_rate
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.mano.mano_file import fix_left_shapedirs
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_layer import ManoHandModel
import numpy as np
import torch

logger = logging.getLogger(__name__)

SOURCE: Final = 'hot3d'
LICENCE: Final = 'HOT3D dataset licence (projectaria.com/datasets/hot3D)'
FPS: Final = 30.0
RGB_STREAM: Final = '214-1'
GREY_STREAM: Final = '1201-1'
SHAPES_FILE: Final = '__hand_shapes.json__'
NUM_PCA: Final = 15
FISHEYE_MODELS: Final = ('CameraModelType.FISHEYE624', 'OculusVisionFishEye624')
PINHOLE_MODELS: Final = ('PinholePlane',)
FISHEYE_PARAMS: Final = 16
_FIELDS: Final = ('global_orient', 'hand_pose', 'betas', 'transl')


@dataclass(frozen=True)
class StreamCamera:
    """One stream's camera in one frame (``cameras.json`` entry).

    Attributes:
        width: image width (px).
        height: image height (px).
        model: ``projection_model_type``.
        params: ``projection_params`` (fx, fy, cx, cy, then distortion coefficients).
        T_world_cam: (4, 4) camera-to-world pose (OpenCV camera).

    """

    width: int
    height: int
    model: str
    params: tuple[float, ...]
    T_world_cam: np.ndarray

    @property
    def K(self) -> np.ndarray:
        """Return the (3, 3) pinhole intrinsics the frames are warped to."""
        fx, fy, cx, cy = self.params[:4]
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def se3_from_json(entry: dict) -> np.ndarray:
    """Return the (4, 4) transform of a ``{translation_xyz, quaternion_wxyz}`` entry."""
    w, x, y, z = (float(v) for v in entry['quaternion_wxyz'])
    return geometry.make_transform(geometry.quaternion_xyzw_to_matrix(np.array([x, y, z, w])),
                                   np.asarray(entry['translation_xyz'], np.float64))


def parse_camera(entry: dict, where: str) -> StreamCamera:
    """Read one stream's ``cameras.json`` entry (InputError if unsupported)."""
    try:
        calib = entry['calibration']
        camera = StreamCamera(int(calib['image_width']), int(calib['image_height']),
                              str(calib['projection_model_type']),
                              tuple(float(v) for v in calib['projection_params']),
                              se3_from_json(entry['T_world_from_camera']))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f'{where}: malformed HOT3D camera entry ({exc})') from exc
    if camera.model in FISHEYE_MODELS and len(camera.params) == FISHEYE_PARAMS:
        return camera
    if camera.model in PINHOLE_MODELS and len(camera.params) >= 4:
        return camera
    raise InputError(f'{where}: unsupported projection {camera.model} with '
                     f'{len(camera.params)} parameters')


def fisheye624_distort(camera: StreamCamera, p: np.ndarray) -> np.ndarray:
    """Apply FISHEYE624's radial, tangential and thin-prism terms to arctan-projected (..., 2)."""
    k = camera.params[4:10]
    p1, p2, s1, s2, s3, s4 = camera.params[10:16]
    theta2 = np.minimum((p * p).sum(axis=-1), np.pi ** 2)
    radial = 1.0 + sum(coeff * theta2 ** (i + 1) for i, coeff in enumerate(k))
    x, y = p[..., 0] * radial, p[..., 1] * radial
    r2 = x * x + y * y
    xd = x + 2.0 * p2 * x * y + p1 * (r2 + 2.0 * x * x) + s1 * r2 + s2 * r2 * r2
    yd = y + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * y * y) + s3 * r2 + s4 * r2 * r2
    return np.stack([xd, yd], axis=-1)


def project_with_calibration(camera: StreamCamera, points_cam: np.ndarray) -> np.ndarray:
    """Project camera-frame points (..., 3) to the stream's original (distorted) pixels."""
    points = np.asarray(points_cam, np.float64)
    fx, fy, cx, cy = camera.params[:4]
    if camera.model in PINHOLE_MODELS:
        uv = points[..., :2] / points[..., 2:]
    else:
        r = np.linalg.norm(points[..., :2], axis=-1)
        scale = np.arctan2(r, points[..., 2]) / np.maximum(r, 1e-12)
        uv = fisheye624_distort(camera, points[..., :2] * scale[..., None])
    return uv * (fx, fy) + (cx, cy)


def pinhole_maps(camera: StreamCamera) -> tuple[np.ndarray, np.ndarray]:
    """Return cv2.remap maps from the pinhole image (``camera.K``) into the original image."""
    fx, fy, cx, cy = camera.params[:4]
    u, v = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones(u.shape)], axis=-1)
    pixels = project_with_calibration(camera, rays).astype(np.float32)
    return pixels[..., 0], pixels[..., 1]


@dataclass(frozen=True)
class ClipFiles:
    """Members of one clip, in a plain tar file or an extracted folder.

    Attributes:
        path: the ``.tar`` file or the folder.
        members: tar member name -> (data offset, size); None for a folder.

    """

    path: Path
    members: dict[str, tuple[int, int]] | None

    @classmethod
    def from_path(cls, path: Path) -> 'ClipFiles':
        """Index a clip (InputError if the tar cannot be read)."""
        if path.is_dir():
            return cls(path, None)
        try:
            with tarfile.open(path, 'r:') as tar:
                members = {m.name: (m.offset_data, m.size) for m in tar.getmembers() if m.isfile()}
        except (OSError, tarfile.TarError) as exc:
            raise InputError(f'{path}: unreadable HOT3D clip ({exc})') from exc
        return cls(path, members)

    def names(self) -> list[str]:
        """Return the member names."""
        if self.members is None:
            return [p.name for p in self.path.iterdir() if p.is_file()]
        return list(self.members)

    def read(self, name: str) -> bytes:
        """Return a member's bytes (InputError if missing)."""
        try:
            if self.members is None:
                return (self.path / name).read_bytes()
            offset, size = self.members[name]
            with self.path.open('rb') as handle:
                handle.seek(offset)
                return handle.read(size)
        except (OSError, KeyError) as exc:
            raise InputError(f'{self.path}: no member {name}') from exc

    def read_json(self, name: str) -> dict:
        """Return a JSON member."""
        try:
            return json.loads(self.read(name))
        except ValueError as exc:
            raise InputError(f'{self.path}/{name}: invalid JSON ({exc})') from exc


class ClipFrames:
    """RGB loader over one stream of a clip, warped from its calibration to the pinhole ``K``."""

    def __init__(self, clip: ClipFiles, stream: str, cameras: list[StreamCamera]) -> None:
        """Hold the clip, the stream id and each frame's camera."""
        self._clip, self._stream, self._cameras = clip, stream, cameras
        self._maps: dict[tuple[float, ...], tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, index: int) -> np.ndarray:
        """Return frame ``index`` as (H, W, 3) uint8 RGB (InputError if unreadable)."""
        name = f'{index:06d}.image_{self._stream}.jpg'
        image = cv2.imdecode(np.frombuffer(self._clip.read(name), np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f'{self._clip.path}/{name}: undecodable image')
        camera = self._cameras[index]
        if camera.model in FISHEYE_MODELS:
            if camera.params not in self._maps:
                self._maps[camera.params] = pinhole_maps(camera)
            map_x, map_y = self._maps[camera.params]
            image = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT)
        return np.ascontiguousarray(image[:, :, ::-1])


def _full_pose(thetas: np.ndarray, data: ManoData) -> np.ndarray:
    """Flat-hand relative (15, 3) pose of smplx PCA coefficients (with the mean pose)."""
    pose = thetas @ data.hands_components[:NUM_PCA] + data.hands_mean
    return pose.reshape(15, 3)


def _world_mano(hands: list[dict | None], side: int, data: ManoData,
                betas: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Frames with this side's MANO (T,) bool and its world MANO arrays (T, ...)."""
    frames = len(hands)
    world = {'global_orient': np.zeros((frames, 3)), 'hand_pose': np.zeros((frames, 15, 3)),
             'betas': np.repeat(betas[None], frames, axis=0), 'transl': np.zeros((frames, 3))}
    present = np.zeros(frames, bool)
    for index, frame in enumerate(hands):
        pose = ((frame or {}).get(SIDE_NAMES[side]) or {}).get('mano_pose')
        if not pose:
            continue
        thetas = np.asarray(pose['thetas'], np.float64).reshape(NUM_PCA)
        xform = np.asarray(pose['wrist_xform'], np.float64).reshape(6)
        world['hand_pose'][index] = _full_pose(thetas, data)
        world['global_orient'][index], world['transl'][index] = xform[:3], xform[3:]
        present[index] = True
    return present, world


def _to_camera(world: dict[str, np.ndarray], model: ManoHandModel,
               T_cam_world: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Camera-frame joints (T, 21, 3) and MANO arrays of one hand's world MANO."""
    tensors = [torch.as_tensor(world[name], dtype=torch.float64) for name in _FIELDS]
    with torch.no_grad():
        joints_world = model(*tensors).joints.numpy()
        roots = model.rest_joints(tensors[2])[:, 0].numpy()
    joints = geometry.transform_points(T_cam_world, joints_world)
    cam = {name: world[name].copy() for name in _FIELDS}
    for index, pose in enumerate(T_cam_world):
        moved = transform_mano_params(ManoParams(*(world[n][index] for n in _FIELDS)),
                                      pose[:3, :3], pose[:3, 3], roots[index])
        cam['global_orient'][index], cam['transl'][index] = moved.global_orient, moved.transl
    return joints, cam


def _frame_count(clip: ClipFiles) -> int:
    frames = [int(n.split('.')[0]) for n in clip.names() if n.endswith('.cameras.json')]
    if not frames:
        raise InputError(f'{clip.path}: no <frame>.cameras.json members')
    return max(frames) + 1


def _stamps(clip: ClipFiles, stream: str, frames: int) -> np.ndarray:
    names = set(clip.names())
    stamps = []
    for index in range(frames):
        name = f'{index:06d}.info.json'
        value = clip.read_json(name).get('image_timestamps_ns', {}).get(stream) \
            if name in names else None
        if value is None:
            return stamps_from_rate(frames, FPS)
        stamps.append(int(value))
    return np.asarray(stamps, np.int64) - stamps[0]


def has_hand_annotations(clip: ClipFiles) -> bool:
    """Return whether a clip has hand poses and shapes (test clips have not)."""
    names = clip.names()
    return SHAPES_FILE in names and any(n.endswith('.hands.json') for n in names)


def read_hot3d_clip(path: Path, mano: tuple[ManoData, ManoData],
                    keep_mano: bool) -> CorpusSequence:
    """Read one HOT3D clip (tar or extracted folder).

    Args:
        path: ``clip-<ID>.tar`` or a folder with its members.
        mano: real MANO arrays (left, right) the clip's MANO parameters belong to.
        keep_mano: keep the clip's MANO (the corpus's hand model is this real MANO), else leave
            it to be fitted.

    """
    clip = ClipFiles.from_path(Path(path))
    frames = _frame_count(clip)
    names = set(clip.names())
    raw = [clip.read_json(f'{i:06d}.cameras.json') for i in range(frames)]
    stream = RGB_STREAM if RGB_STREAM in raw[0] else GREY_STREAM
    cameras = []
    for index, entry in enumerate(raw):
        if stream not in entry:
            raise InputError(f'{clip.path}: frame {index} has no camera {stream}')
        cameras.append(parse_camera(entry[stream], f'{clip.path}/{index:06d}.cameras.json'))
    betas = np.asarray(clip.read_json(SHAPES_FILE)['mano'], np.float64).reshape(NUM_BETAS)
    hands = [clip.read_json(f'{i:06d}.hands.json') if f'{i:06d}.hands.json' in names else None
             for i in range(frames)]
    fixed = (fix_left_shapedirs(mano[LEFT], mano[RIGHT]), mano[RIGHT])
    T_world_cam = np.stack([camera.T_world_cam for camera in cameras])
    T_cam_world = geometry.invert_transform(T_world_cam)
    present, joints, valid = empty_hands(frames)
    mano_cam = {name: np.zeros((frames, len(SIDES), *shape)) for name, shape in
                zip(_FIELDS, ((3,), (15, 3), (NUM_BETAS,), (3,)))}
    for side in SIDES:
        has, world = _world_mano(hands, side, fixed[side], betas)
        if not has.any():
            continue
        model = ManoHandModel(fixed[side], dtype=torch.float64)
        side_joints, cam = _to_camera(world, model, T_cam_world)
        present[:, side] = has
        valid[:, side] = has[:, None]
        joints[has, side] = side_joints[has]
        for field in _FIELDS:
            mano_cam[field][has, side] = cam[field][has]
    first = cameras[0]
    return CorpusSequence(
        sequence_id=f'{clip.path.parent.name}.{clip.path.name.removesuffix(".tar")}',
        source=SOURCE, licence=LICENCE, image_size=(first.width, first.height),
        timestamp_ns=_stamps(clip, stream, frames),
        K=np.stack([camera.K for camera in cameras]),
        T_world_cam=rebase_to_first(T_world_cam), hand_present=present, joints_cam=joints,
        joint_valid=valid, mano_cam=mano_cam if keep_mano else None,
        read_rgb=ClipFrames(clip, stream, cameras))


def iter_hot3d(roots: list[Path], mano: tuple[ManoData, ManoData],
               keep_mano: bool) -> Iterator[CorpusSequence]:
    """Yield every annotated clip (``clip-*.tar`` or ``clip-*/``) under each root, sorted."""
    for root in map(Path, roots):
        candidates = [root] if root.name.startswith('clip-') else sorted(root.glob('**/clip-*'))
        for path in candidates:
            if not (path.is_dir() or path.suffix == '.tar'):
                continue
            if not has_hand_annotations(ClipFiles.from_path(path)):
                logger.info('%s: no hand annotations (a test clip?), skipped', path)
                continue
            yield read_hot3d_clip(path, mano, keep_mano)
