"""Write a prepared corpus sequence as one sample directory (``data/sample_format.py``).

The directory appears atomically (``core.atomic_io``): RGB JPEGs, hand-label PNGs, the
annotations and ``meta.json``, whose ``sequence`` object carries the source, the licence and
whether the sequence has a camera trajectory. No depth directory is written (the reader then
reports depth as unknown).
"""

import json
from pathlib import Path

import cv2
from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import honour_umask
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.corpus.prepare import PreparedSequence
import numpy as np
from safetensors.numpy import save_file


def sequence_info(prepared: PreparedSequence) -> dict:
    """Return the ``meta.json`` ``sequence`` object of a prepared sequence."""
    sequence = prepared.sequence
    return {'id': sequence.sequence_id, 'source': sequence.source,
            'licence': sequence.licence,
            'camera_trajectory': sequence.has_camera_trajectory,
            'mano_fitted': sequence.mano_cam is None}


def write_sample_directory(prepared: PreparedSequence, path: Path) -> None:
    """Write ``prepared`` to the new directory ``path`` (InputError if it exists)."""
    sequence = prepared.sequence
    with atomic_directory(path) as work:
        (work / fmt.RGB_DIR).mkdir(parents=True)
        (work / fmt.MASK_DIR).mkdir()
        for index in range(sequence.num_frames):
            rgb = sequence.read_rgb(index)
            cv2.imwrite(str(work / fmt.RGB_DIR / fmt.frame_file(index, fmt.RGB_SUFFIX)),
                        np.ascontiguousarray(rgb[:, :, ::-1]),
                        [cv2.IMWRITE_JPEG_QUALITY, fmt.JPEG_QUALITY])
            cv2.imwrite(str(work / fmt.MASK_DIR / fmt.frame_file(index, fmt.PNG_SUFFIX)),
                        prepared.labels[index])
        save_file({key: np.ascontiguousarray(value)
                   for key, value in prepared.annotations.items()},
                  str(work / fmt.ANNOTATIONS_FILE))
        honour_umask(work / fmt.ANNOTATIONS_FILE)
        width, height = sequence.image_size
        meta = {'format': fmt.FORMAT_NAME, 'version': fmt.FORMAT_VERSION,
                'frames': sequence.num_frames, 'width': width, 'height': height,
                'sequence': sequence_info(prepared)}
        (work / fmt.META_FILE).write_text(json.dumps(meta, indent=2), encoding='utf-8')
