"""Input discovery: command-line paths to the bags and videos to convert, in a stable order.

A path is a rosbag2 bag directory (``metadata.yaml`` plus MCAP or sqlite3 files, split files
included), a bare ``.mcap`` file, a ROS 1 ``.bag`` file, a video file (an animated GIF
included), an image sequence (a folder with JPEG or PNG files directly inside: one episode), or
a folder searched recursively for those (sorted by path). A storage file inside a bag directory
stands for its bag. Paths that name nothing usable are returned as failures with the reason.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Final

from infinihand_ros.convert.image_frames import image_files

#: The file rosbag2 writes into every bag directory.
BAG_METADATA: Final = 'metadata.yaml'
#: Storage files read as bags on their own (MCAP, ROS 1) or through their directory (sqlite3).
BAG_SUFFIXES: Final = ('.mcap', '.db3', '.bag')
VIDEO_SUFFIXES: Final = ('.mp4', '.mkv', '.mov', '.avi', '.webm', '.gif')
BAG: Final = 'bag'
VIDEO: Final = 'video'
IMAGES: Final = 'images'


@dataclass(frozen=True)
class InputSource:
    """One input to convert.

    Attributes:
        path: resolved path of the bag (directory or file), the video file or the folder of
            images.
        kind: 'bag', 'video' or 'images'.

    """

    path: Path
    kind: str


@dataclass(frozen=True)
class InputFailure:
    """A command-line path that could not be used, with the reason."""

    path: Path
    reason: str


def _is_bag_dir(path: Path) -> bool:
    return path.is_dir() and (path / BAG_METADATA).is_file()


def _classify_file(path: Path) -> InputSource | None:
    """Return the input a file stands for (its bag directory for a split file), or None."""
    suffix = path.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        return InputSource(path, VIDEO)
    if suffix in BAG_SUFFIXES:
        return InputSource(path.parent if _is_bag_dir(path.parent) else path, BAG)
    return None


def _search_folder(folder: Path) -> list[InputSource]:
    """Return the inputs below ``folder`` (bag directories are not entered).

    A folder with image files directly inside is an image sequence (its subfolders are still
    searched).
    """
    found: list[InputSource] = [InputSource(folder, IMAGES)] if image_files(folder) else []
    for child in sorted(folder.iterdir()):
        if _is_bag_dir(child):
            found.append(InputSource(child, BAG))
        elif child.is_dir():
            found.extend(_search_folder(child))
        elif child.is_file():
            source = _classify_file(child)
            if source is not None:
                found.append(source)
    return found


def discover_inputs(paths: list[Path]) -> tuple[list[InputSource], list[InputFailure]]:
    """Expand command-line paths into inputs (deduplicated, first occurrence kept).

    Args:
        paths: bags, bag storage files, videos or folders of them.

    Returns:
        (inputs to convert, paths that name no usable input with the reason).

    """
    sources: list[InputSource] = []
    failures: list[InputFailure] = []
    for path in paths:
        path = Path(path).expanduser().resolve()
        if not path.exists():
            failures.append(InputFailure(path, 'does not exist'))
        elif _is_bag_dir(path):
            sources.append(InputSource(path, BAG))
        elif path.is_dir():
            found = _search_folder(path)
            if not found:
                failures.append(InputFailure(path, 'folder holds no rosbag2 bag, .mcap, .bag, '
                                                   f'video file ({", ".join(VIDEO_SUFFIXES)}) '
                                                   'or image sequence (.jpg, .png files)'))
            sources.extend(found)
        else:
            source = _classify_file(path)
            if source is None:
                failures.append(InputFailure(
                    path, f'not a bag ({", ".join(BAG_SUFFIXES)} or a rosbag2 directory) or a '
                          f'video ({", ".join(VIDEO_SUFFIXES)})'))
            else:
                sources.append(source)
    unique = list(dict.fromkeys(sources))
    return unique, failures
