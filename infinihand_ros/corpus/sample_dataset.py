"""PyTorch dataset over sample directories (``data/sample_format.py``)."""

from pathlib import Path

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.corpus import sample_format as fmt
import numpy as np
from safetensors import safe_open
import torch
from torch.utils.data import Dataset


def _read_meta(root: Path) -> dict:
    """Read ``meta.json`` of a sample directory and check its format and version."""
    meta = fmt.read_meta(root)
    if meta.get('format') != fmt.FORMAT_NAME or meta.get('version') != fmt.FORMAT_VERSION:
        raise InputError(f'{root / fmt.META_FILE}: format {meta.get("format")!r} version '
                         f'{meta.get("version")!r}; expected {fmt.FORMAT_NAME!r} version '
                         f'{fmt.FORMAT_VERSION}')
    return meta


class SampleDataset(Dataset):
    """Frames of one or more sample directories as dictionaries of tensors.

    Each item holds ``rgb`` (H, W, 3) uint8, ``masks`` (2, H, W) bool (left, right), ``depth``
    (H, W) float32 metres (0 = nothing) and every annotation of that frame (see the format).
    """

    def __init__(self, roots: str | Path | list[str | Path]) -> None:
        """Index the frames of ``roots`` (one directory or a list)."""
        root_list = [roots] if isinstance(roots, (str, Path)) else list(roots)
        self._index: list[tuple[Path, int]] = []
        self._annotations: dict[Path, dict[str, torch.Tensor]] = {}
        for root in map(Path, root_list):
            meta = _read_meta(root)
            with safe_open(str(root / fmt.ANNOTATIONS_FILE), framework='pt') as handle:
                self._annotations[root] = {key: handle.get_tensor(key) for key in handle.keys()}
            self._index.extend((root, i) for i in range(meta['frames']))

    def __len__(self) -> int:
        """Return the number of frames over all directories."""
        return len(self._index)

    def __getitem__(self, item: int) -> dict[str, torch.Tensor]:
        """Load frame ``item``."""
        root, index = self._index[item]
        rgb = cv2.imread(str(root / fmt.RGB_DIR / fmt.frame_file(index, fmt.RGB_SUFFIX)))
        png = fmt.frame_file(index, fmt.PNG_SUFFIX)
        labels = cv2.imread(str(root / fmt.MASK_DIR / png), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(root / fmt.DEPTH_DIR / png), cv2.IMREAD_UNCHANGED)
        if rgb is None or labels is None or depth is None:
            raise InputError(f'{root}: frame {index} has a missing or unreadable image file')
        sample = {key: value[index] for key, value in self._annotations[root].items()}
        sample['rgb'] = torch.from_numpy(np.ascontiguousarray(rgb[:, :, ::-1]))
        sample['masks'] = torch.from_numpy(np.stack([labels == label
                                                     for label in fmt.SIDE_LABELS]))
        sample['depth'] = torch.from_numpy(depth.astype(np.float32) / fmt.DEPTH_UNITS_PER_M)
        return sample
