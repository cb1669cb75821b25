"""One sequence of the unified corpus in memory, whatever dataset it came from.

Adapters turn a dataset's layout into ``CorpusSequence`` objects in our conventions (OpenCV
optical camera frame, metres, 21 joints in OpenPose order, side axis [left, right], MANO of our
hand models); ``prepare.complete_sequence`` fills in what a dataset lacks (MANO fitted to joints,
masks, boxes, 2D and world joints) and ``sample_writer`` stores it in the sample format.
"""

from collections.abc import Callable
from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
import numpy as np

#: Loads frame ``index`` of a sequence as (H, W, 3) uint8 RGB.
RgbLoader = Callable[[int], np.ndarray]
#: Loads frame ``index``'s (H, W) uint8 hand labels (0 none, 1 left, 2 right).
LabelLoader = Callable[[int], np.ndarray]


@dataclass(frozen=True)
class CorpusSequence:
    """A sequence's frames and camera-space hand annotations (T frames).

    Attributes:
        sequence_id: unique within its source (letters, digits, '-', '_', '.').
        source: dataset name (e.g. 'arctic').
        licence: licence of the source's data, as its authors state it.
        image_size: (width, height) pixels.
        timestamp_ns: (T,) int64 frame stamps.
        K: (T, 3, 3) intrinsics, pixels.
        T_world_cam: (T, 4, 4) camera-to-world poses, or None when the dataset has none.
        hand_present: (T, 2) bool, the hand is annotated.
        joints_cam: (T, 2, 21, 3) camera-frame joints (m), NaN where unknown.
        joint_valid: (T, 2, 21) bool, which joints are annotated.
        mano_cam: camera-frame MANO arrays by field ('global_orient' (T, 2, 3), 'hand_pose'
            (T, 2, 15, 3), 'betas' (T, 2, 10), 'transl' (T, 2, 3)), or None to fit them.
        read_rgb: loader of the RGB frames.
        read_labels: loader of annotated hand labels, or None to render masks.
        hand_confidence: (T, 2) confidence of each hand-frame's label in [0, 1] (pseudo-labels),
            or None for annotated datasets (stored as 1 where a hand is present).

    """

    sequence_id: str
    source: str
    licence: str
    image_size: tuple[int, int]
    timestamp_ns: np.ndarray
    K: np.ndarray
    T_world_cam: np.ndarray | None
    hand_present: np.ndarray
    joints_cam: np.ndarray
    joint_valid: np.ndarray
    mano_cam: dict[str, np.ndarray] | None
    read_rgb: RgbLoader
    read_labels: LabelLoader | None = None
    hand_confidence: np.ndarray | None = None

    def __post_init__(self) -> None:
        frames = len(self.timestamp_ns)
        shapes = {'K': (self.K, (frames, 3, 3)),
                  'hand_present': (self.hand_present, (frames, 2)),
                  'joints_cam': (self.joints_cam, (frames, 2, 21, 3)),
                  'joint_valid': (self.joint_valid, (frames, 2, 21))}
        if self.hand_confidence is not None:
            shapes['hand_confidence'] = (self.hand_confidence, (frames, 2))
        if self.T_world_cam is not None:
            shapes['T_world_cam'] = (self.T_world_cam, (frames, 4, 4))
        for name, (value, shape) in shapes.items():
            if np.shape(value) != shape:
                raise InputError(f'sequence {self.sequence_id}: {name} has shape '
                                 f'{np.shape(value)}, expected {shape}')
        if not self.sequence_id or not all(c.isalnum() or c in '-_.' for c in self.sequence_id):
            raise InputError(f'sequence id {self.sequence_id!r}: use letters, digits, - _ .')

    @property
    def num_frames(self) -> int:
        """Return the number of frames."""
        return len(self.timestamp_ns)

    @property
    def has_camera_trajectory(self) -> bool:
        """Return whether the sequence has camera poses (Stage II)."""
        return self.T_world_cam is not None
