"""Write synthetic frames in the training-sample form of ``data/sample_format.py``, atomically."""

import contextlib
import json
from pathlib import Path
from typing import Final

import cv2
from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import honour_umask
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np
from safetensors.numpy import save_file

#: Sub-directory of a generator output directory that holds its training samples.
SAMPLES_DIR: Final = 'samples'


def _encode_depth(depth: np.ndarray) -> np.ndarray:
    """Metres (+inf = nothing) to uint16 millimetres (0 = nothing)."""
    units = np.where(np.isfinite(depth), np.round(depth * fmt.DEPTH_UNITS_PER_M), 0)
    return np.clip(units, 0, fmt.MAX_DEPTH_UNITS).astype(np.uint16)


class SampleSink:
    """Context manager collecting ``SynthFrame``s into a new sample directory."""

    def __init__(self, path: str | Path, sequence_info: dict) -> None:
        """Prepare a sample directory at ``path`` (must not exist).

        Args:
            path: directory to create.
            sequence_info: JSON-serialisable description stored in ``meta.json``.

        """
        self.path = Path(path)
        self.sequence_info = sequence_info
        self._stack = contextlib.ExitStack()
        self._work: Path | None = None
        self._rows: list[dict[str, np.ndarray]] = []
        self._image_size: tuple[int, int] | None = None

    def __enter__(self) -> 'SampleSink':
        """Create the directory tree under a temporary name."""
        self._work = self._stack.enter_context(atomic_directory(self.path))
        for sub in (fmt.RGB_DIR, fmt.MASK_DIR, fmt.DEPTH_DIR):
            (self._work / sub).mkdir(parents=True)
        return self

    def __exit__(self, exc_type: object, exc: object, traceback: object) -> None:
        """Write the annotations and metadata, then move the directory into place."""
        if exc_type is None and self._work is not None:
            self._write_annotations()
        self._stack.__exit__(exc_type, exc, traceback)
        self._work = None

    def add(self, frame: SynthFrame) -> None:
        """Write one frame's images and keep its annotations."""
        if self._work is None:
            raise RuntimeError('SampleSink.add called outside its with-block')
        self._image_size = (frame.rgb.shape[1], frame.rgb.shape[0])
        name = fmt.frame_file(len(self._rows), fmt.RGB_SUFFIX)
        cv2.imwrite(str(self._work / fmt.RGB_DIR / name), frame.rgb[:, :, ::-1],
                    [cv2.IMWRITE_JPEG_QUALITY, fmt.JPEG_QUALITY])
        labels = np.zeros(frame.rgb.shape[:2], np.uint8)
        for hand in frame.hands:
            labels[hand.mask] = fmt.SIDE_LABELS[hand.side]
        png = fmt.frame_file(len(self._rows), fmt.PNG_SUFFIX)
        cv2.imwrite(str(self._work / fmt.MASK_DIR / png), labels)
        cv2.imwrite(str(self._work / fmt.DEPTH_DIR / png), _encode_depth(frame.depth))
        self._rows.append(self._annotation_row(frame))

    @staticmethod
    def _annotation_row(frame: SynthFrame) -> dict[str, np.ndarray]:
        """Per-frame annotation arrays with a side axis of length 2."""
        sides = len(SIDES)
        row = {
            'timestamp_ns': np.array(frame.timestamp_ns, np.int64),
            'K': frame.intrinsics.matrix(),
            'T_world_cam': frame.camera_pose.matrix(),
            'hand_present': np.zeros(sides, bool),
            'visible': np.zeros(sides, bool),
            'joints_cam': np.zeros((sides, NUM_JOINTS, 3)),
            'joints_world': np.zeros((sides, NUM_JOINTS, 3)),
            'joints_2d': np.zeros((sides, NUM_JOINTS, 2)),
            'box_xyxy': np.zeros((sides, 4)),
        }
        for frame_name in ('mano_cam', 'mano_world'):
            for field, shape in zip(fmt.MANO_FIELDS, ((3,), (15, 3), (10,), (3,))):
                row[f'{frame_name}_{field}'] = np.zeros((sides,) + shape)
        for hand in frame.hands:
            s = hand.side
            row['hand_present'][s] = True
            row['visible'][s] = hand.visible
            for key in ('joints_cam', 'joints_world', 'joints_2d', 'box_xyxy'):
                row[key][s] = getattr(hand, key)
            for frame_name in ('mano_cam', 'mano_world'):
                params = getattr(hand, frame_name)
                for field in fmt.MANO_FIELDS:
                    row[f'{frame_name}_{field}'][s] = getattr(params, field)
        return row

    def _write_annotations(self) -> None:
        """Stack the rows into arrays and write annotations.safetensors and meta.json."""
        arrays = {key: np.ascontiguousarray(np.stack([row[key] for row in self._rows]))
                  for key in self._rows[0]} if self._rows else {}
        save_file(arrays, str(self._work / fmt.ANNOTATIONS_FILE))
        honour_umask(self._work / fmt.ANNOTATIONS_FILE)
        width, height = self._image_size or (0, 0)
        meta = {'format': fmt.FORMAT_NAME, 'version': fmt.FORMAT_VERSION,
                'frames': len(self._rows), 'width': width, 'height': height,
                'sequence': self.sequence_info}
        (self._work / fmt.META_FILE).write_text(json.dumps(meta, indent=2), encoding='utf-8')
