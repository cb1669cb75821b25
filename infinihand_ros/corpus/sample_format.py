"""The training-sample form of a sequence: small image files plus one safetensors of annotations.

Layout of a sample directory (written atomically, version ``FORMAT_VERSION``)::

    meta.json                  format name and version, frame count, image size, sequence info
                               (the generator's: ``distortion_model`` and ``distortion``, the
                               images' lens, None and [] for a pinhole camera)
    rgb/000000.jpg ...         RGB frames (JPEG, quality 95)
    masks/000000.png ...       uint8 hand labels: 0 background, 1 left hand, 2 right hand
    depth/000000.png ...       uint16 depth in millimetres along the optical axis, 0 = nothing
    annotations.safetensors    per-frame arrays, side axis [0 left, 1 right]:
        timestamp_ns (T,) int64, K (T, 3, 3), T_world_cam (T, 4, 4) (world = first camera),
        hand_present (T, 2) bool (the hand exists in the sequence), visible (T, 2) bool,
        {mano_cam, mano_world}_{global_orient (T, 2, 3), hand_pose (T, 2, 15, 3),
        betas (T, 2, 10), transl (T, 2, 3)}, joints_cam / joints_world (T, 2, 21, 3) metres,
        joints_2d (T, 2, 21, 2) pixels, box_xyxy (T, 2, 4) pixels; float arrays are float64.

Images load with one OpenCV call each and annotations are memory-mapped, so a PyTorch dataset
(``data/synth_dataset.py``) reads a sample in about a millisecond.
"""

import json
from pathlib import Path
from typing import Final

from infinihand_ros.core.errors import InputError

FORMAT_NAME: Final = 'infinihand-samples'
FORMAT_VERSION: Final = 1
META_FILE: Final = 'meta.json'
ANNOTATIONS_FILE: Final = 'annotations.safetensors'
RGB_DIR: Final = 'rgb'
MASK_DIR: Final = 'masks'
DEPTH_DIR: Final = 'depth'
RGB_SUFFIX: Final = '.jpg'
PNG_SUFFIX: Final = '.png'
JPEG_QUALITY: Final = 95
#: Mask label of each side (index 0 left, 1 right); 0 is background.
SIDE_LABELS: Final = (1, 2)
#: Depth PNGs store millimetres in uint16; 0 means no surface.
DEPTH_UNITS_PER_M: Final = 1000.0
MAX_DEPTH_UNITS: Final = 65535
#: Annotation keys of the MANO parameter groups.
MANO_FIELDS: Final = ('global_orient', 'hand_pose', 'betas', 'transl')


def frame_file(index: int, suffix: str) -> str:
    """File name of frame ``index`` (zero-padded to six digits)."""
    return f'{index:06d}{suffix}'


def read_meta(root: Path) -> dict:
    """Return the ``meta.json`` object of a sample directory ``root``.

    Raises:
        InputError: naming the file when it is missing, not JSON or not a JSON object.

    """
    meta_path = Path(root) / META_FILE
    try:
        meta = json.loads(meta_path.read_text(encoding='utf-8'))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f'{meta_path}: not a readable sample directory ({exc}); generate one '
                         'with python -m infinihand_ros.synth') from exc
    if not isinstance(meta, dict):
        raise InputError(f'{meta_path}: expected a JSON object, got {type(meta).__name__}')
    return meta
