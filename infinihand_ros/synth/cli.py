"""Command line: generate a synthetic sequence as a bag, training samples and preview PNGs.

``python -m infinihand_ros.synth --out DIR --seed S --frames N [--fps F --width W --height H
--hands both|left|right --distortion MODEL:COEFFS --format mcap|sqlite3 --compress --image-codec
raw|jpeg|png]`` writes into DIR::

    bag/                    rosbag2 bag (MCAP or sqlite3) with images and ground truth
    samples/                training samples (data/sample_format.py)
    preview_frames.png      contact sheet of frames with the ground-truth skeletons
    preview_trajectory.png  top view of the camera and wrist paths
    synth_config.yaml       the resolved settings and seed
"""

import argparse
from dataclasses import asdict
from dataclasses import replace
import logging
from pathlib import Path
import sys
import time
from typing import Final

import cv2
from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.synth import preview
from infinihand_ros.synth.bag_sink import BagOptions
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.bag_sink import IMAGE_CODECS
from infinihand_ros.synth.bag_sink import STORAGE_PLUGINS
from infinihand_ros.synth.sample_sink import SAMPLES_DIR
from infinihand_ros.synth.sample_sink import SampleSink
from infinihand_ros.synth.sequence import HAND_CHOICES
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
from infinihand_ros.synth.sequence import SynthFrame
from infinihand_ros.synth.trajectory_plot import plot_top_view
import numpy as np
from tqdm import tqdm
import yaml

logger = logging.getLogger(__name__)

BAG_DIR: Final = 'bag'
FRAMES_PREVIEW: Final = 'preview_frames.png'
TRAJECTORY_PREVIEW: Final = 'preview_trajectory.png'
RESOLVED_CONFIG: Final = 'synth_config.yaml'
PREVIEW_TILES: Final = 8
PREVIEW_COLUMNS: Final = 4
MAX_FRAMES: Final = 1_000_000


def build_parser() -> argparse.ArgumentParser:
    """Arguments of the generator (defaults of optional settings come from config/synth.yaml)."""
    parser = argparse.ArgumentParser(
        prog='python -m infinihand_ros.synth',
        description='Generate a synthetic egocentric sequence with exact hand and camera ground '
                    'truth: a rosbag2 bag, training samples and preview PNGs.')
    parser.add_argument('--out', required=True, type=Path, help='output directory (new or empty)')
    parser.add_argument('--seed', required=True, type=int, help='random seed (non-negative)')
    parser.add_argument('--frames', required=True, type=int, help='number of frames')
    parser.add_argument('--fps', type=float, help='frame rate in Hz (default 10)')
    parser.add_argument('--width', type=int, help='image width in px (default 518)')
    parser.add_argument('--height', type=int, help='image height in px (default 378)')
    parser.add_argument('--hands', choices=sorted(HAND_CHOICES), help='hands shown (default both)')
    parser.add_argument('--distortion', metavar='MODEL:COEFFS',
                        help='render through this lens, as CameraInfo has it: '
                        'plumb_bob:k1,k2,p1,p2,k3, rational_polynomial:k1,..,k6 (8 values) or '
                        'equidistant:k1,k2,k3,k4, e.g. plumb_bob:-0.25,0.08,0,0,0 (default: '
                        "none, a pinhole camera); the bag's CameraInfo and the ground truth "
                        'carry it')
    parser.add_argument('--format', dest='storage', choices=sorted(STORAGE_PLUGINS),
                        help='bag storage (default mcap)')
    parser.add_argument('--compress', action='store_true', default=None,
                        help='zstd-compress the bag')
    parser.add_argument('--image-codec', choices=IMAGE_CODECS,
                        help='raw: sensor_msgs/Image rgb8 (default); jpeg or png: '
                             'sensor_msgs/CompressedImage on /camera/image_raw/compressed')
    parser.add_argument('--config', type=Path, help='settings file (default: config/synth.yaml)')
    return parser


def validate_args(args: argparse.Namespace) -> tuple[SynthConfig, BagOptions]:
    """Check the arguments and return the resolved sequence and bag settings.

    Raises:
        InfiniHandError: naming the bad argument and the accepted values.

    """
    if args.seed < 0:
        raise InfiniHandError(f'--seed must be >= 0, got {args.seed}')
    if not 1 <= args.frames <= MAX_FRAMES:
        raise InfiniHandError(f'--frames must be within 1..{MAX_FRAMES}, got {args.frames}')
    if args.out.exists() and (not args.out.is_dir() or any(args.out.iterdir())):
        raise InfiniHandError(f'--out {args.out} exists and is not an empty directory; '
                              'choose a new path')
    check_writable_location(args.out, '--out')
    path = args.config or config_dir() / 'synth.yaml'
    config = load_config(path, 'synth', SynthConfig)
    bag_options = load_config(path, 'bag', BagOptions)

    def overrides(keys: tuple[str, ...]) -> dict:
        return {key: getattr(args, key) for key in keys if getattr(args, key) is not None}

    return (replace(config, **overrides(('fps', 'width', 'height', 'hands', 'distortion'))),
            replace(bag_options, **overrides(('storage', 'compress', 'image_codec'))))


def _preview_tile(frame: SynthFrame) -> np.ndarray:
    """Return a copy of the frame with the visible hands' ground-truth skeletons drawn."""
    image = frame.rgb.copy()
    for hand in frame.hands:
        if hand.visible:
            image = preview.draw_skeleton(image, hand.joints_2d, hand.side)
    return image


def generate(config: SynthConfig, seed: int, frames: int, out: Path,
             bag_options: BagOptions | None = None, progress: bool = True) -> dict:
    """Generate one sequence into ``out``; return a summary with the measured speed."""
    start = time.perf_counter()
    sequence = SyntheticSequence(config, seed, frames)
    preview_indices = set(np.linspace(0, frames - 1, min(PREVIEW_TILES, frames)).astype(int))
    tiles, labels = [], []
    bag_options = bag_options or BagOptions()
    with BagSink(out / BAG_DIR, bag_options) as bag, \
            SampleSink(out / SAMPLES_DIR, sequence.describe()) as samples:
        for frame in tqdm(sequence, total=frames, desc='synth', unit='frame',
                          disable=not progress):
            bag.add(frame)
            samples.add(frame)
            if frame.index in preview_indices:
                tiles.append(_preview_tile(frame))
                labels.append(f'#{frame.index}  t={frame.index / config.fps:.1f}s')
    elapsed = time.perf_counter() - start
    sheet = preview.contact_sheet(tiles, PREVIEW_COLUMNS, labels)
    for name, image in ((FRAMES_PREVIEW, sheet), (TRAJECTORY_PREVIEW, plot_top_view(sequence))):
        ok, png = cv2.imencode('.png', image[:, :, ::-1])
        if not ok:
            raise InfiniHandError(f'could not encode {name}')
        atomic_write_bytes(out / name, png.tobytes())
    resolved = {'synth': asdict(config), 'bag': asdict(bag_options), 'seed': seed,
                'frames': frames, 'sequence': sequence.describe()}
    atomic_write_bytes(out / RESOLVED_CONFIG, yaml.safe_dump(resolved, sort_keys=False).encode())
    return {'frames': frames, 'seconds': elapsed, 'fps': frames / elapsed, 'out': str(out)}


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        config, bag_options = validate_args(args)
        summary = generate(config, args.seed, args.frames, args.out, bag_options)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:  # e.g. the disk filled up while writing
        print(f'error: writing --out {args.out} failed: {exc}', file=sys.stderr)
        return 1
    print(f"wrote {summary['frames']} frames to {summary['out']} in {summary['seconds']:.1f} s "
          f"({summary['fps']:.1f} frames/s)")
    return 0
