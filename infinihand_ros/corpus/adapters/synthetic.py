"""Adapter of our own synthetic sequences (sample directories written by ``synth``).

They are already in our conventions, with exact MANO, joints, masks and camera poses, so the
adapter only maps the arrays; every generated sequence has a camera trajectory (Stage II).
"""

from collections.abc import Iterator
from pathlib import Path
from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.corpus.sequence import RgbLoader
import numpy as np
from safetensors.numpy import load_file

SOURCE: Final = 'infinihand-synth'
LICENCE: Final = 'Apache-2.0'


def _image_loader(root: Path, sub: str, suffix: str, flags: int) -> RgbLoader:
    """Return a loader of frame images (RGB for colour, as stored otherwise)."""

    def load(index: int) -> np.ndarray:
        path = root / sub / fmt.frame_file(index, suffix)
        image = cv2.imread(str(path), flags)
        if image is None:
            raise InputError(f'{path}: missing or unreadable image')
        return np.ascontiguousarray(image[:, :, ::-1]) if image.ndim == 3 else image
    return load


def read_synthetic_sequence(root: Path) -> CorpusSequence:
    """Read one synthetic sample directory (InputError for another format)."""
    meta = fmt.read_meta(root)
    if meta.get('format') != fmt.FORMAT_NAME:
        raise InputError(f'{root}: format {meta.get("format")!r}, expected {fmt.FORMAT_NAME!r}')
    arrays = load_file(str(root / fmt.ANNOTATIONS_FILE))
    present = arrays['hand_present'].astype(bool)
    seed = meta.get('sequence', {}).get('seed', root.name)
    return CorpusSequence(
        sequence_id=f'{root.name}-seed{seed}', source=SOURCE, licence=LICENCE,
        image_size=(int(meta['width']), int(meta['height'])),
        timestamp_ns=arrays['timestamp_ns'], K=arrays['K'], T_world_cam=arrays['T_world_cam'],
        hand_present=present, joints_cam=arrays['joints_cam'],
        joint_valid=np.repeat(present[..., None], arrays['joints_cam'].shape[2], axis=2),
        mano_cam={name: arrays[f'mano_cam_{name}'] for name in fmt.MANO_FIELDS},
        read_rgb=_image_loader(root, fmt.RGB_DIR, fmt.RGB_SUFFIX, cv2.IMREAD_COLOR),
        read_labels=_image_loader(root, fmt.MASK_DIR, fmt.PNG_SUFFIX, cv2.IMREAD_UNCHANGED))


def iter_synthetic(paths: list[Path]) -> Iterator[CorpusSequence]:
    """Yield the synthetic sequences in or below ``paths``, sorted."""
    for path in paths:
        metas = [path / fmt.META_FILE] if (path / fmt.META_FILE).is_file() \
            else sorted(Path(path).rglob(fmt.META_FILE))
        for meta in metas:
            yield read_synthetic_sequence(meta.parent)
