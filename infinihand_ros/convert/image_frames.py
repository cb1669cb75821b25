"""Frames of an image sequence: a folder of JPEG or PNG files, one episode, sorted by name.

Egocentric datasets ship frames this way (EPIC-KITCHENS' ``rgb_frames/``). The files carry no
times: frame ``i`` is stamped ``i / input_fps``. An unreadable file is skipped and counted;
every frame carries the intrinsics given on the command line, or None (predicted).
"""

from collections.abc import Iterator
from pathlib import Path

import cv2
from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.convert.video_frames import matching_intrinsics
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.units import NS_PER_S

#: Files an image sequence is made of (case-insensitive).
IMAGE_SUFFIXES = ('.jpg', '.jpeg', '.png')
UNREADABLE = 'image file that cannot be decoded'


def image_files(folder: Path) -> list[Path]:
    """Return the image files directly inside ``folder``, sorted by name."""
    return sorted(path for path in folder.iterdir()
                  if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES)


def read_image_frames(folder: Path, input_fps: float | None, intrinsics: Intrinsics | None,
                      log: FrameLog) -> Iterator[SourceFrame]:
    """Yield the RGB frames of the image sequence in ``folder``.

    Raises:
        InputError: without ``input_fps`` (the files carry no times), naming the folder.

    """
    if input_fps is None or not input_fps > 0:
        raise InputError(f'image sequence {folder}: its files carry no times; pass the rate '
                         'they were taken at with --input-fps (e.g. --input-fps 30)')
    for index, path in enumerate(image_files(folder)):
        log.read += 1
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            log.skip(UNREADABLE)
            continue
        rgb = bgr[..., ::-1].copy()
        yield SourceFrame(round(index * NS_PER_S / input_fps), rgb,
                          matching_intrinsics(intrinsics, rgb.shape[1], rgb.shape[0], folder,
                                              log))
