"""Command line ``bag_to_dataset INPUT... --output DIR``: bags and videos to a LeRobot dataset.

Exit codes: 0 when every input converted (or was already in the dataset), 1 when at least one
input failed (all others are converted and written), 2 for usage errors (bad flags, settings,
output directory, or a Ray cluster that cannot be reached), 130 when interrupted (the dataset
keeps every finished episode). ``--ray`` runs the inputs on Ray (``ray_run``; Ray itself is
imported only then); the dataset is the same as the local run's.
"""

import argparse
from dataclasses import replace
import json
import logging
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.dataset_writer import DatasetWriter
from infinihand_ros.convert.image_fit import RESIZE_MODES
from infinihand_ros.convert.inputs import discover_inputs
from infinihand_ros.convert.inputs import IMAGES
from infinihand_ros.convert.inputs import InputSource
from infinihand_ros.convert.ray_run import convert_on_ray
from infinihand_ros.convert.ray_run import RayStartError
from infinihand_ros.convert.report import EpisodeReport
from infinihand_ros.convert.report import FAILED
from infinihand_ros.convert.report import summary_table
from infinihand_ros.convert.run import ConversionRun
from infinihand_ros.convert.run import engine_config_for
from infinihand_ros.convert.run import resolve_video_size
from infinihand_ros.convert.run import RunOptions
from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.distortion import parse_distortion
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.settings import add_settings_arguments
from infinihand_ros.engine.settings import save_engine_settings
from infinihand_ros.engine.settings import SETTINGS_FILE
from tqdm import tqdm

EXIT_OK: Final = 0
EXIT_FAILED: Final = 1
EXIT_USAGE: Final = 2
EXIT_INTERRUPTED: Final = 130
REPORT_FILE: Final = 'conversion_report.json'


class UsageError(Exception):
    """A flag, setting or output directory that makes the run impossible."""


def build_parser() -> argparse.ArgumentParser:
    """Arguments of bag_to_dataset (defaults of optional ones come from config/convert.yaml)."""
    parser = argparse.ArgumentParser(
        prog='bag_to_dataset',
        description='Convert rosbag2/ROS 1 bags and videos into a LeRobot v3.0 dataset of hand '
                    'demonstrations (one episode per input or per time window).')
    parser.add_argument('inputs', nargs='+', type=Path, metavar='INPUT',
                        help='bag directory, .mcap/.bag file, video (GIF included), image '
                             'sequence (a folder of JPEG/PNG frames), or folder of them')
    parser.add_argument('--output', required=True, type=Path, help='dataset directory (new, '
                        'or one written by bag_to_dataset: it is resumed and extended)')
    parser.add_argument('--fps', type=int, help='output frame rate in Hz (default 10)')
    parser.add_argument('--task', help='task string of every episode (default: the sidecar '
                        '<input>.task.txt, else "demonstration")')
    parser.add_argument('--image-topic', help='image topic of the bags (default: auto-detect)')
    parser.add_argument('--input-fps', type=float, metavar='HZ',
                        help='rate of image-sequence inputs (folders of JPEG/PNG frames, '
                             'sorted by name; their files carry no times)')
    parser.add_argument('--episode-seconds', type=float,
                        help='split inputs into episodes of at most this many seconds')
    parser.add_argument('--intrinsics', help='fx,fy,cx,cy,width,height of video and image inputs '
                        '(default: predicted by the model)')
    parser.add_argument('--distortion', metavar='MODEL:COEFFS',
                        help='lens distortion of --intrinsics, as CameraInfo has it: '
                        'plumb_bob:k1,k2,p1,p2,k3, rational_polynomial:k1,k2,p1,p2,k3,k4,k5,k6 '
                        'or equidistant:k1,k2,k3,k4 (fisheye), e.g. plumb_bob:-0.25,0.08,0,0,0 '
                        '(default: none, a pinhole camera; bags carry their own)')
    parser.add_argument('--video-size', metavar='WxH', help="size of the dataset's videos; "
                        'inputs of another size are fitted to it, intrinsics mapped (default: '
                        "the existing dataset's, else the first input's)")
    parser.add_argument('--resize', choices=RESIZE_MODES, help='how inputs of another size '
                        'are fitted: letterbox (scaled, padded black; the default) or crop '
                        '(scaled, centre-cropped)')
    add_settings_arguments(parser, None, 'convert.engine.profile in --config: offline')
    parser.add_argument('--no-ba', action='store_true',
                        help='turn bundle adjustment off (as --set bundle_adjustment=null)')
    parser.add_argument('--no-estimates-bag', action='store_true',
                        help='do not write the MCAP bag of estimates per episode')
    parser.add_argument('--config', type=Path, help='converter settings (default: '
                        'config/convert.yaml)')
    parser.add_argument('--ray', nargs='?', const='', metavar='ADDRESS',
                        help='convert on a Ray cluster, one task per input: ADDRESS of the '
                        'cluster (auto, HOST:6379, ray://HOST:10001), or none for RAY_ADDRESS, '
                        'the cluster last started here, else a new local instance; the output '
                        'must be on storage every node sees')
    parser.add_argument('--quiet', action='store_true', help='no progress bars')
    return parser


def _intrinsics(text: str | None, distortion: str | None = None) -> Intrinsics | None:
    if text is None:
        if distortion is not None:
            raise UsageError(f'--distortion {distortion!r} needs --intrinsics (the lens '
                             'distorts the pinhole camera they describe)')
        return None
    parts = text.split(',')
    try:
        if len(parts) != 6:
            raise ValueError(f'{len(parts)} values')
        fx, fy, cx, cy = (float(part) for part in parts[:4])
        intrinsics = Intrinsics(fx, fy, cx, cy, int(parts[4]), int(parts[5]))
    except ValueError as exc:
        raise UsageError(f'--intrinsics {text!r}: expected fx,fy,cx,cy,width,height '
                         f'({exc})') from exc
    if distortion is None:
        return intrinsics
    try:
        model, coefficients = parse_distortion(distortion)
    except InputError as exc:
        raise UsageError(str(exc)) from exc
    return replace(intrinsics, distortion_model=model, distortion=coefficients)


def validate_args(args: argparse.Namespace) -> tuple[ConvertConfig, RunOptions]:
    """Return the settings and options the arguments describe.

    Raises:
        UsageError: for a bad settings file or value, or an output that cannot be written.

    """
    try:
        config = load_convert_config(args.config)
        engine = config.engine
        if args.profile is not None:
            engine = replace(engine, profile=args.profile)
        if args.engine_config is not None:
            engine = replace(engine, config=str(args.engine_config))
        extra = tuple(args.overrides) + (('bundle_adjustment=null',) if args.no_ba else ())
        engine = replace(engine, overrides=engine.overrides + extra)
        layout = config.dataset
        if args.video_size is not None:
            layout = replace(layout, video_size=args.video_size)
        if args.resize is not None:
            layout = replace(layout, resize=args.resize)
        overrides = {'engine': engine, 'dataset': layout}
        for key, value in (('fps', args.fps), ('task', args.task),
                           ('episode_max_s', args.episode_seconds)):
            if value is not None:
                overrides[key] = value
        if args.no_estimates_bag:
            overrides['estimates_bag'] = False
        config = replace(config, **overrides)
        check_writable_location(args.output, '--output')
    except InfiniHandError as exc:
        raise UsageError(str(exc)) from exc
    if args.input_fps is not None and not args.input_fps > 0:
        raise UsageError(f'--input-fps {args.input_fps}: expected a rate above 0 (Hz)')
    intrinsics = _intrinsics(args.intrinsics, args.distortion)
    return config, RunOptions(args.output, args.image_topic, intrinsics,
                              progress=not args.quiet, input_fps=args.input_fps)


def _check_input_rates(sources: list[InputSource], options: RunOptions) -> None:
    """Refuse image sequences without ``--input-fps`` before anything is converted."""
    untimed = [str(source.path) for source in sources if source.kind == IMAGES]
    if untimed and options.input_fps is None:
        raise UsageError(f'image sequences carry no times ({", ".join(untimed)}); pass the rate '
                         'they were taken at with --input-fps (e.g. --input-fps 30)')


def _finish(reports: list[EpisodeReport], output: Path) -> None:
    """Print every report and the summary; save them beside the dataset."""
    for report in reports:
        print('\n'.join(report.lines()))
    print(summary_table(reports))
    data = json.dumps([report.to_dict() for report in reports], indent=2)
    (output / REPORT_FILE).write_text(data, encoding='utf-8')


def convert_locally(sources: list[InputSource], config: ConvertConfig, options: RunOptions,
                    writer: DatasetWriter, reports: list[EpisodeReport]) -> None:
    """Convert ``sources`` one after the other in this process; append to ``reports``."""
    run = ConversionRun(config, options, writer, reports)
    try:
        for source in tqdm(sources, desc='inputs', unit='input', disable=not options.progress):
            run.convert(source)
    finally:
        run.close()


def main(argv: list[str] | None = None) -> int:
    """Run the converter; return the exit code."""
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        config, options = validate_args(args)
        engine_settings = engine_config_for(config)  # a bad --set is refused before any work
        writer = DatasetWriter(options.output, config)
    except (UsageError, InfiniHandError) as exc:
        print(f'bag_to_dataset: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    sources, failures = discover_inputs(args.inputs)
    try:
        _check_input_rates(sources, options)
        config = resolve_video_size(config, writer.video_size, sources, options)
    except (UsageError, InfiniHandError) as exc:
        print(f'bag_to_dataset: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    reports = [EpisodeReport(str(f.path), status=FAILED, error=f.reason) for f in failures]
    interrupted = False
    try:
        if args.ray is None:
            convert_locally(sources, config, options, writer, reports)
        else:
            convert_on_ray(args.ray or None, sources, config, options, writer, reports)
    except KeyboardInterrupt:
        interrupted = True
        print(f'interrupted: the dataset keeps its {writer.num_episodes} finished episodes',
              file=sys.stderr)
    except RayStartError as exc:  # nothing was converted
        print(f'bag_to_dataset: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    save_engine_settings(engine_settings, options.output / SETTINGS_FILE, config.engine.profile,
                         config.engine.overrides)  # beside the report, as the run ends
    _finish(reports, options.output)
    if interrupted:
        return EXIT_INTERRUPTED
    return EXIT_FAILED if any(r.status == FAILED for r in reports) else EXIT_OK


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())
