"""Format-driven sequence readers and the per-sequence training targets built from them.

A reader opens one sequence directory and gives its frame count, source image size, the
annotation arrays (keys and layout of ``data/sample_format.py``, side axis [left, right]) and
per-frame images. ``open_sequence`` picks the reader from ``meta.json``'s ``format`` through a
mapping of format names to reader factories (``SAMPLE_READERS`` by default), so a real-dataset
adapter plugs in by passing its own mapping; it need not write every annotation: a missing key
reads as NaN (or False for flags), which the losses leave out of their valid sets.

``build_targets`` does every per-sequence computation once, when the dataset is built: the
annotations mapped to the model input (``engine.frame_input.fit_image`` geometry, so training
sees the frames exactly as the engine does), the FoV targets and the validity flags. Per clip
only the images are decoded and fitted.
"""

from collections.abc import Callable
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
import types
from typing import Final, Protocol

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.engine.frame_input import fit_image
from infinihand_ros.engine.frame_input import FrameMapping
from infinihand_ros.model.config import GeometryConfig
import numpy as np
from safetensors import safe_open

#: Target keys of a clip item (``ClipDataset``), each with a leading clip-frame axis S.
IMAGES: Final = 'images'            # (S, 3, H, W) uint8 RGB at the model size
MASKS: Final = 'masks'              # (S, 2, H, W) uint8 hand masks, 255 = hand
MASK_VALID: Final = 'mask_valid'    # (S, 2) bool, the mask annotation exists
DEPTH: Final = 'depth'              # (S, H, W) float32 depth at the model size (m), 0 = unknown
INTRINSICS: Final = 'intrinsics'    # (S, 3, 3) float64 K at the model size
T_WORLD_CAM: Final = 'T_world_cam'  # (S, 4, 4) float64 camera-to-world, dataset world
CAMERA_VALID: Final = 'camera_valid'  # (S,) bool
FOV: Final = 'fov'                  # (S, 2) float64 (fov_h, fov_w) rad at the model size
HAND_PRESENT: Final = 'hand_present'  # (S, 2) bool, MANO and joint annotations exist
BOX_VALID: Final = 'box_valid'      # (S, 2) bool, the hand is visible with a non-empty box
BOXES: Final = 'boxes'              # (S, 2, 4) float32 tight boxes, model pixels
JOINTS_CAM: Final = 'joints_cam'    # (S, 2, 21, 3) float64 camera frame, m
JOINTS_WORLD: Final = 'joints_world'  # (S, 2, 21, 3) float64 dataset world, m
JOINTS_2D: Final = 'joints_2d'      # (S, 2, 21, 2) float64 model pixels
MANO_KEYS: Final = tuple(f'mano_{name}' for name in fmt.MANO_FIELDS)  # camera-frame MANO
FRAME_INDEX: Final = 'frame_index'  # (S,) long, frame of the sequence
SEQUENCE_INDEX: Final = 'sequence_index'  # () long, the sequence among the dataset's
#: Per-frame target arrays ``build_targets`` returns (everything but the images and masks).
TARGET_KEYS: Final = (MASK_VALID, INTRINSICS, T_WORLD_CAM, CAMERA_VALID, FOV, HAND_PRESENT,
                      BOX_VALID, BOXES, JOINTS_CAM, JOINTS_WORLD, JOINTS_2D, *MANO_KEYS)
_MANO_SHAPES: Final = {'global_orient': (3,), 'hand_pose': (15, 3), 'betas': (10,),
                       'transl': (3,)}


class SequenceReader(Protocol):
    """What the training data needs of one sequence, whatever its storage."""

    num_frames: int
    image_size: tuple[int, int]  # (width, height) of the source frames, pixels

    def annotations(self) -> dict[str, np.ndarray]:
        """Return the per-frame annotation arrays (sample-format keys; missing keys allowed)."""

    def read_rgb(self, index: int) -> np.ndarray:
        """Return frame ``index`` as (H, W, 3) uint8 RGB."""

    def read_hand_labels(self, index: int) -> np.ndarray | None:
        """Return (H, W) uint8 labels (0 none, 1 left, 2 right), or None without masks."""

    def read_depth(self, index: int) -> np.ndarray | None:
        """Return (H, W) float32 depth in metres (0 = unknown), or None without depth."""


ReaderFactory = Callable[[Path, dict], SequenceReader]


class SampleDirectoryReader:
    """Reader of the training-sample form (``data/sample_format.py``), version 1."""

    def __init__(self, root: Path, meta: dict) -> None:
        """Check the format version and index the directory.

        Raises:
            InputError: for another version or a broken ``meta.json``.

        """
        if meta.get('version') != fmt.FORMAT_VERSION:
            raise InputError(f'{root / fmt.META_FILE}: version {meta.get("version")!r}; this '
                             f'reader reads version {fmt.FORMAT_VERSION}')
        try:
            self.num_frames = int(meta['frames'])
            self.image_size = (int(meta['width']), int(meta['height']))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f'{root / fmt.META_FILE}: needs integer frames, width and height '
                             f'({exc})') from exc
        self.root = root

    def annotations(self) -> dict[str, np.ndarray]:
        """Return every array of ``annotations.safetensors``."""
        path = self.root / fmt.ANNOTATIONS_FILE
        try:
            with safe_open(str(path), framework='np') as handle:
                return {key: handle.get_tensor(key) for key in handle.keys()}
        except (OSError, ValueError) as exc:
            raise InputError(f'{path}: unreadable annotations ({exc})') from exc

    def read_rgb(self, index: int) -> np.ndarray:
        """Return frame ``index`` as RGB (InputError when the file is missing)."""
        path = self.root / fmt.RGB_DIR / fmt.frame_file(index, fmt.RGB_SUFFIX)
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f'{path}: missing or unreadable frame image')
        return np.ascontiguousarray(image[:, :, ::-1])

    def read_hand_labels(self, index: int) -> np.ndarray | None:
        """Return the label PNG of frame ``index``, or None when the sequence has no masks."""
        directory = self.root / fmt.MASK_DIR
        if not directory.is_dir():
            return None
        path = directory / fmt.frame_file(index, fmt.PNG_SUFFIX)
        labels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if labels is None:
            raise InputError(f'{path}: missing or unreadable hand-label image')
        return labels

    def read_depth(self, index: int) -> np.ndarray | None:
        """Return the depth of frame ``index`` in metres, or None when the sequence has none."""
        directory = self.root / fmt.DEPTH_DIR
        if not directory.is_dir():
            return None
        path = directory / fmt.frame_file(index, fmt.PNG_SUFFIX)
        depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16:
            raise InputError(f'{path}: missing or unreadable uint16 depth image')
        return depth.astype(np.float32) / np.float32(fmt.DEPTH_UNITS_PER_M)


#: Reader factories by ``meta.json`` format name (read-only; pass your own mapping to add).
SAMPLE_READERS: Final[Mapping[str, ReaderFactory]] = types.MappingProxyType(
    {fmt.FORMAT_NAME: SampleDirectoryReader})


def open_sequence(root: str | Path,
                  readers: Mapping[str, ReaderFactory] = SAMPLE_READERS) -> SequenceReader:
    """Open one sequence directory with the reader of its ``meta.json`` format.

    Raises:
        InputError: for a missing or broken ``meta.json`` or a format no reader reads.

    """
    root = Path(root)
    meta = fmt.read_meta(root)
    name = meta.get('format')
    if name not in readers:
        raise InputError(f'{root / fmt.META_FILE}: format {name!r} has no reader; known '
                         f'formats are {sorted(readers)}')
    return readers[name](root, meta)


def find_sequences(paths: tuple[str, ...] | list[str]) -> list[Path]:
    """Return the sequence directories of ``paths``: each one or those found under it, sorted.

    Raises:
        InputError: for a path that does not exist or holds no sequence.

    """
    found: list[Path] = []
    for text in paths:
        path = Path(text)
        if (path / fmt.META_FILE).is_file():
            found.append(path)
            continue
        if not path.is_dir():
            raise InputError(f'training data {path}: no such directory; generate sequences '
                             'with python -m infinihand_ros.synth or fix train.data.sequences')
        below = sorted(meta.parent for meta in path.rglob(fmt.META_FILE))
        if not below:
            raise InputError(f'training data {path}: no sequence directory ({fmt.META_FILE}) '
                             'below it')
        found.extend(below)
    return found


@dataclass(frozen=True)
class FrameFitter:
    """Fits source frames and their masks to the model input, as the engine does."""

    config: GeometryConfig

    def mapping(self, image_size: tuple[int, int]) -> FrameMapping:
        """Return the pixel mapping of a (width, height) source frame."""
        width, height = image_size
        _, mapping = fit_image(np.zeros((height, width, 3), np.uint8),
                               self.config.preprocessing, self.config.aggregator)
        return mapping

    def fit_rgb(self, rgb: np.ndarray) -> np.ndarray:
        """Return the (3, H, W) uint8 model input of an (h, w, 3) RGB frame."""
        fitted, _ = fit_image(rgb, self.config.preprocessing, self.config.aggregator)
        return np.ascontiguousarray(fitted.transpose(2, 0, 1))

    def fit_masks(self, labels: np.ndarray) -> np.ndarray:
        """Return (2, H, W) uint8 masks (255 = hand) of (h, w) labels, the RGB's geometry."""
        planes = np.zeros((*labels.shape, 3), np.uint8)
        for side, label in enumerate(fmt.SIDE_LABELS):
            planes[..., side] = np.where(labels == label, 255, 0)
        fitted, mapping = fit_image(planes, self.config.preprocessing, self.config.aggregator)
        x0, y0, x1, y1 = mapping.content_box
        masks = np.zeros((2, *fitted.shape[:2]), np.uint8)  # padding is never a hand
        masks[:, y0:y1, x0:x1] = fitted[y0:y1, x0:x1, :2].transpose(2, 0, 1)
        return masks

    def fit_depth(self, depth: np.ndarray) -> np.ndarray:
        """Return (H, W) float32 model-size depth of an (h, w) map (nearest; padding 0)."""
        mapping = self.mapping((depth.shape[1], depth.shape[0]))
        x0, y0, x1, y1 = mapping.content_box
        width, height = mapping.model_size
        fitted = np.zeros((height, width), np.float32)
        fitted[y0:y1, x0:x1] = cv2.resize(depth, (x1 - x0, y1 - y0),
                                          interpolation=cv2.INTER_NEAREST)
        return fitted


def _array(annotations: dict[str, np.ndarray], key: str, shape: tuple[int, ...],
           frames: int) -> np.ndarray:
    """Return annotation ``key`` as float64 (frames, *shape), NaN when it is missing."""
    if key not in annotations:
        return np.full((frames, *shape), np.nan)
    value = np.asarray(annotations[key], dtype=np.float64)
    if value.shape != (frames, *shape):
        raise InputError(f'annotation {key!r}: expected shape {(frames, *shape)}, got '
                         f'{value.shape}')
    return value


def _flags(annotations: dict[str, np.ndarray], key: str, frames: int) -> np.ndarray:
    """Return flag annotation ``key`` as bool (frames, 2), all False when it is missing."""
    if key not in annotations:
        return np.zeros((frames, 2), bool)
    return np.asarray(annotations[key], dtype=bool).reshape(frames, 2)


def _boxes_to_model(boxes: np.ndarray, mapping: FrameMapping) -> np.ndarray:
    """Map tight (x0, y0, x1, y1) boxes (exclusive x1, y1) from source to model pixels."""
    corners = boxes.reshape(*boxes.shape[:-1], 2, 2) - 0.5  # pixel edges, centre coordinates
    return (mapping.points_to_model(corners) + 0.5).reshape(boxes.shape)


def build_targets(reader: SequenceReader, config: GeometryConfig,
                  has_masks: bool) -> dict[str, np.ndarray]:
    """Return the per-frame targets of a sequence at the model input (see ``TARGET_KEYS``).

    Args:
        reader: the open sequence.
        config: the model's geometry config (input size and preprocessing).
        has_masks: the sequence has hand-label images.

    Raises:
        InputError: for an annotation of the wrong shape.

    """
    frames = reader.num_frames
    raw = reader.annotations()
    mapping = FrameFitter(config).mapping(reader.image_size)
    scale = np.diag([mapping.scale_x, mapping.scale_y, 1.0])
    scale[:2, 2] = (mapping.offset_x, mapping.offset_y)
    intrinsics = scale @ _array(raw, 'K', (3, 3), frames)
    T_world_cam = _array(raw, T_WORLD_CAM, (4, 4), frames)
    width, height = mapping.model_size
    # The encoding's FoVs (pose_encoding.cam_to_world_to_encoding): 2 atan((size / 2) / f).
    fov = np.stack((2.0 * np.arctan((height / 2.0) / intrinsics[:, 1, 1]),
                    2.0 * np.arctan((width / 2.0) / intrinsics[:, 0, 0])), axis=-1)
    present = _flags(raw, 'hand_present', frames)
    boxes = _boxes_to_model(_array(raw, 'box_xyxy', (2, 4), frames), mapping)
    box_area_ok = np.all(np.isfinite(boxes), axis=-1) & (boxes[..., 2] > boxes[..., 0]) \
        & (boxes[..., 3] > boxes[..., 1])
    targets = {
        MASK_VALID: np.full((frames, 2), has_masks),
        INTRINSICS: intrinsics,
        T_WORLD_CAM: T_world_cam,
        CAMERA_VALID: np.all(np.isfinite(T_world_cam), axis=(-2, -1))
        & np.all(np.isfinite(intrinsics), axis=(-2, -1)),
        FOV: fov,
        HAND_PRESENT: present,
        BOX_VALID: present & _flags(raw, 'visible', frames) & box_area_ok,
        BOXES: np.nan_to_num(boxes).astype(np.float32),
        JOINTS_CAM: _array(raw, 'joints_cam', (2, NUM_JOINTS, 3), frames),
        JOINTS_WORLD: _array(raw, 'joints_world', (2, NUM_JOINTS, 3), frames),
        JOINTS_2D: mapping.points_to_model(_array(raw, 'joints_2d', (2, NUM_JOINTS, 2),
                                                  frames)),
    }
    for name, shape in _MANO_SHAPES.items():
        targets[f'mano_{name}'] = _array(raw, f'mano_cam_{name}', (2, *shape), frames)
    return targets
