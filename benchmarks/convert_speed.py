"""Frames/s of bag_to_dataset on a short synthetic bag, and where the time goes.

    python benchmarks/convert_speed.py [--frames 20] [--width 320] [--height 240] [--ba]
        [--image-codec jpeg] [--ray-workers 1 2]

Renders a synthetic sequence into an MCAP bag (``python -m infinihand_ros.synth``), then times
each stage alone over the same frames with the settings of ``config/convert.yaml`` (BA only with
``--ba``): bag reading (message deserialisation, after one untimed pass), image decoding (of
``--image-codec`` images), the engine, and writing (video
encoding with image statistics, the MCAP bag of estimates, the parquet data file); last, the
whole conversion through the command line. Prints frames/s per stage and each stage's share of
the stages' sum. With
``--ray-workers`` it also converts ``max(workers)`` copies of the bag with ``--ray`` on a local
Ray instance of that many CPUs, once per worker count. Figures, not a test: they depend on the
machine and on what else runs on it.
"""

import argparse
import contextlib
from dataclasses import replace
import io
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time

from infinihand_ros.bag.reader import BagReader
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.convert import lerobot_layout
from infinihand_ros.convert.bag_frames import read_bag_frames
from infinihand_ros.convert.cli import main as bag_to_dataset
from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.estimates_bag import EstimatesBagWriter
from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.convert.lerobot_features import ACTION
from infinihand_ros.convert.lerobot_features import DEFAULT_FEATURES
from infinihand_ros.convert.lerobot_features import frame_values
from infinihand_ros.convert.lerobot_features import SOURCE_STAMP
from infinihand_ros.convert.lerobot_features import STATE
from infinihand_ros.convert.lerobot_features import TIMESTAMP
from infinihand_ros.convert.run import engine_config_for
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.convert.stats import ImageStats
from infinihand_ros.convert.topic_selection import select_image_topic
from infinihand_ros.convert.video_writer import EpisodeVideoWriter
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.engine.streaming_engine import StreamingEngine
import numpy as np
import pyarrow.parquet as pq
import yaml


def _synth_bag(out: Path, frames: int, width: int, height: int, codec: str) -> Path:
    subprocess.run([sys.executable, '-m', 'infinihand_ros.synth', '--out', str(out), '--seed',
                    '0', '--frames', str(frames), '--width', str(width), '--height', str(height),
                    '--image-codec', codec], check=True, capture_output=True)
    return out / 'bag'


def _timed(stage: str, timings: dict[str, float], run: object) -> object:
    start = time.perf_counter()
    value = run()
    timings[stage] = time.perf_counter() - start
    return value


def _read_only(bag: Path) -> int:
    with BagReader(bag) as reader:
        topic = select_image_topic(reader.topics(), str(bag), None)
        return sum(1 for _ in reader.messages([topic]))


def _run_engine(engine: StreamingEngine, frames: list[SourceFrame]) -> list[FrameResult]:
    results: list[FrameResult] = []
    for frame in frames:
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    return results + engine.flush()


def _write(frames: list[SourceFrame], results: list[FrameResult], work: Path,
           config: ConvertConfig, timings: dict[str, float]) -> None:
    """Time the three writers of an episode over already converted frames."""
    def video() -> None:
        stats = ImageStats()
        writer = EpisodeVideoWriter(work / 'video.mp4', config.fps, config.video)
        for frame in frames:
            writer.write(frame.rgb)
            stats.add(frame.rgb)
        writer.close()

    def estimates() -> None:
        writer = EstimatesBagWriter(work / 'estimates', build_typestore(),
                                    config.estimates_path_length)
        for result in results:
            writer.write(result)
        writer.close()

    def data() -> None:
        values = [frame_values(result, config.dataset.invalid_fill)[0] for result in results]
        columns = {key: np.stack([v[key] for v in values]) for key in values[0]}
        count = len(results)
        columns[ACTION] = columns[STATE]
        for key in (SOURCE_STAMP, *DEFAULT_FEATURES):
            columns[key] = np.arange(count, dtype=np.int64)[:, None]
        columns[TIMESTAMP] = (np.arange(count) / config.fps)[:, None]
        pq.write_table(lerobot_layout.data_table(columns), io.BytesIO())

    _timed('write: video + image stats', timings, video)
    _timed('write: estimates bag', timings, estimates)
    _timed('write: data parquet', timings, data)


def _print(timings: dict[str, float], frames: int) -> None:
    total = sum(timings.values())
    print(f'{"stage":<28} {"frames/s":>10} {"share":>7}')
    for stage, seconds in timings.items():
        print(f'{stage:<28} {frames / seconds:>10.1f} {100 * seconds / total:>6.1f}%')
    print(f'{"sum of stages":<28} {frames / total:>10.1f}')


def _end_to_end(inputs: list[Path], output: Path, ba: bool, *flags: str) -> float:
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the run's reports
        bag_to_dataset([*map(str, inputs), '--output', str(output), '--quiet',
                        *([] if ba else ['--no-ba']), *flags])
    return time.perf_counter() - start


def _ray_runs(bag: Path, root: Path, ba: bool, workers: list[int], frames: int) -> None:
    import ray
    copies = [shutil.copytree(bag, root / f'copy{k}' / 'bag') for k in range(max(workers))]
    for count in workers:
        config_path = root / f'ray{count}.yaml'
        config_path.write_text(yaml.safe_dump({'convert': {'ray': {'workers': count}}}),
                               encoding='utf-8')
        ray.init(num_cpus=count, include_dashboard=False, configure_logging=False)
        try:
            seconds = _end_to_end(copies, root / f'ray{count}', ba, '--config',
                                  str(config_path), '--ray')
        finally:
            ray.shutdown()
        print(f'--ray, {count} workers, {len(copies)} bags: '
              f'{len(copies) * frames / seconds:.1f} frames/s (actor start-up and model '
              'loading included)')


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=20)
    parser.add_argument('--width', type=int, default=320)
    parser.add_argument('--height', type=int, default=240)
    parser.add_argument('--ba', action='store_true', help='bundle adjustment on')
    parser.add_argument('--image-codec', choices=('raw', 'jpeg', 'png'), default='jpeg')
    parser.add_argument('--ray-workers', type=int, nargs='*', default=[])
    args = parser.parse_args()
    config = load_convert_config()
    config = replace(config, engine=replace(config.engine, bundle_adjustment=args.ba))
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        bag = _synth_bag(root / 'synth', args.frames, args.width, args.height,
                         args.image_codec)
        timings: dict[str, float] = {}
        _read_only(bag)
        _timed('bag reading', timings, lambda: _read_only(bag))
        frames = _timed('image decoding', timings,
                        lambda: list(read_bag_frames(bag, None, FrameLog())))
        timings['image decoding'] -= timings['bag reading']
        engine = StreamingEngine(engine_config_for(config))
        results = _timed('engine', timings, lambda: _run_engine(engine, frames))
        engine.close()
        _write(frames, results, root, config, timings)
        print(f'{len(frames)} {args.image_codec} frames {args.width}x{args.height}, BA '
              f'{"on" if args.ba else "off"}')
        _print(timings, len(frames))
        seconds = _end_to_end([bag], root / 'dataset', args.ba)
        print(f'bag_to_dataset end to end: {len(frames) / seconds:.1f} frames/s '
              '(engine start-up included)')
        if args.ray_workers:
            _ray_runs(bag, root, args.ba, args.ray_workers, len(frames))


if __name__ == '__main__':
    main()
