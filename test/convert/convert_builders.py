"""Builders of the converter tests: tiny synthetic bags, bad bags and a fast converter config."""

from pathlib import Path
import subprocess
import sys

from infinihand_ros.bag.camera_msgs import camera_info_to_msg
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import CAMERA_INFO_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.core.datatypes import Intrinsics
import numpy as np
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
import yaml

WIDTH = 160
HEIGHT = 120
BASE_NS = 1_767_225_600_000_000_000
PERIOD_NS = 100_000_000


def synth_bag(out: Path, seed: int, frames: int, *extra: str) -> Path:
    """Generate a synthetic sequence with the project's generator; return its bag directory."""
    subprocess.run([sys.executable, '-m', 'infinihand_ros.synth', '--out', str(out), '--seed',
                    str(seed), '--frames', str(frames), '--width', str(WIDTH), '--height',
                    str(HEIGHT), *extra], check=True, capture_output=True)
    return out / 'bag'


def image_bag(path: Path, images: list[tuple[int, str, np.ndarray]],
              image_topic: str = '/camera/image_raw', with_info: bool = True) -> Path:
    """Write a bag of Image messages given as (stamp_ns, encoding, pixels) and CameraInfo.

    Messages are stored in list order (bag times increase even where header stamps do not).
    """
    store = build_typestore()
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    image_conn = writer.add_connection(image_topic, IMAGE_MSG, typestore=store)
    info_conn = writer.add_connection('/camera/camera_info', CAMERA_INFO_MSG, typestore=store)
    for position, (stamp, encoding, pixels) in enumerate(images):
        bag_time = BASE_NS + 2 * position
        height, width = pixels.shape[:2]
        header = store.types[HEADER_MSG](stamp=stamp_from_ns(store, stamp), frame_id='cam')
        msg = store.types[IMAGE_MSG](header=header, height=height, width=width,
                                     encoding=encoding, is_bigendian=0,
                                     step=pixels.nbytes // height,
                                     data=np.frombuffer(pixels.tobytes(), np.uint8))
        writer.write(image_conn, bag_time, store.serialize_cdr(msg, IMAGE_MSG))
        if with_info:
            info = camera_info_to_msg(store, Intrinsics(100.0, 100.0, width / 2, height / 2,
                                                        width, height), stamp, 'cam')
            writer.write(info_conn, bag_time + 1, store.serialize_cdr(info, CAMERA_INFO_MSG))
    writer.close()
    return path


def rgb_frames(count: int, seed: int = 0) -> list[np.ndarray]:
    """Return ``count`` random (HEIGHT, WIDTH, 3) uint8 frames."""
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8) for _ in range(count)]


def fast_config(path: Path, **overrides: object) -> Path:
    """Write a converter config without bundle adjustment (fast tests); return its path."""
    settings = {'fps': 10, 'engine': {'overrides': ['bundle_adjustment=null']}}
    settings.update(overrides)
    path.write_text(yaml.safe_dump({'convert': settings}), encoding='utf-8')
    return path
