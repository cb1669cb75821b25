"""End-to-end tests of bag_to_dataset (infinihand_ros/convert/cli.py): outputs read back."""

import dataclasses
import errno
import json
from pathlib import Path
import re
import shutil

import av
from convert_builders import BASE_NS
from convert_builders import fast_config
from convert_builders import HEIGHT
from convert_builders import image_bag
from convert_builders import PERIOD_NS
from convert_builders import rgb_frames
from convert_builders import WIDTH
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.convert import dataset_writer
from infinihand_ros.convert import run as run_module
from infinihand_ros.convert.cli import EXIT_FAILED
from infinihand_ros.convert.cli import EXIT_INTERRUPTED
from infinihand_ros.convert.cli import EXIT_OK
from infinihand_ros.convert.cli import EXIT_USAGE
from infinihand_ros.convert.cli import main
from infinihand_ros.convert.cli import REPORT_FILE
from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.config import VideoSettings
from infinihand_ros.convert.estimates_bag import CAMERA_INFO_TOPIC
from infinihand_ros.convert.estimates_bag import HAND_FRAME_TOPIC
from infinihand_ros.convert.estimates_bag import MARKERS_TOPIC
from infinihand_ros.convert.lerobot_features import CAMERA_FLAG_NAMES
from infinihand_ros.convert.lerobot_features import CAMERA_FLAGS
from infinihand_ros.convert.lerobot_features import CAMERA_POSE
from infinihand_ros.convert.lerobot_features import FRAME_FEATURES
from infinihand_ros.convert.video_writer import EpisodeVideoWriter
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
import numpy as np
import pyarrow.parquet as pq
import pytest

FPS = 10
VIDEO_KEY = 'observation.images.ego'


def _convert(inputs: list[Path], output: Path, tmp_path: Path, *flags: str) -> int:
    config = fast_config(tmp_path / 'convert.yaml')
    return main([*map(str, inputs), '--output', str(output), '--config', str(config), '--quiet',
                 *flags])


def _report(output: Path) -> list[dict]:
    return json.loads((output / REPORT_FILE).read_text())


def _read_dataset(root: Path) -> tuple[dict, list[dict]]:
    info = json.loads((root / 'meta/info.json').read_text())
    episodes = pq.read_table(root / 'meta/episodes/chunk-000/file-000.parquet').to_pylist()
    return info, episodes


def _check_dataset(root: Path) -> None:
    """Read every output back: counts, indices, exact timestamps, videos, stats."""
    info, episodes = _read_dataset(root)
    assert info['codebase_version'] == 'v3.0' and info['robot_type'] == 'hand'
    assert info['fps'] == FPS and info['total_episodes'] == len(episodes)
    assert info['total_frames'] == sum(e['length'] for e in episodes)
    stats = json.loads((root / 'meta/stats.json').read_text())
    next_index = 0
    for number, episode in enumerate(episodes):
        assert episode['episode_index'] == number
        assert episode['dataset_from_index'] == next_index
        data = pq.read_table(root / info['data_path'].format(
            chunk_index=episode['data/chunk_index'], file_index=episode['data/file_index']))
        length = episode['length']
        assert data.num_rows == length
        columns = data.to_pydict()
        assert columns['frame_index'] == list(range(length))
        assert columns['index'] == list(range(next_index, next_index + length))
        assert set(columns['episode_index']) == {number}
        np.testing.assert_array_equal(np.array(columns['timestamp'], np.float32),
                                      (np.arange(length) / FPS).astype(np.float32))
        for spec in FRAME_FEATURES:
            assert info['features'][spec.key]['names'] == list(spec.names)
            assert set(stats[spec.key]) >= {'min', 'max', 'mean', 'std', 'count', 'q50'}
            if spec.shape != (1,):
                assert data.schema.field(spec.key).type.list_size == spec.shape[0]
        state = np.array(columns['observation.state'])
        np.testing.assert_array_equal(np.array(columns['action'])[:-1], state[1:])
        valid = np.array(columns['hands.valid'])
        assert valid.shape == (length, 2)
        video = root / info['video_path'].format(
            video_key=VIDEO_KEY, chunk_index=episode[f'videos/{VIDEO_KEY}/chunk_index'],
            file_index=episode[f'videos/{VIDEO_KEY}/file_index'])
        with av.open(str(video)) as container:
            times = [frame.time for frame in container.decode(video=0)]
        np.testing.assert_allclose(times, np.arange(length) / FPS, atol=1e-4)
        assert episode[f'videos/{VIDEO_KEY}/to_timestamp'] == pytest.approx(length / FPS)
        next_index += length
    tasks = pq.read_table(root / 'meta/tasks.parquet')
    assert tasks.schema.pandas_metadata['index_columns'] == ['task']
    assert info['total_tasks'] == tasks.num_rows


@pytest.mark.slow
def test_bags_convert_and_read_back(synth_bags: list[Path], tmp_path: Path) -> None:
    """MCAP/rgb8 and sqlite3/jpeg bags become two episodes whose every output reads back."""
    output = tmp_path / 'dataset'
    assert _convert(synth_bags, output, tmp_path, '--task', 'pick the cup') == EXIT_OK
    _check_dataset(output)
    info, episodes = _read_dataset(output)
    assert [e['length'] for e in episodes] == [6, 6]
    assert [e['tasks'] for e in episodes] == [['pick the cup']] * 2
    assert info['features'][VIDEO_KEY]['shape'] == [HEIGHT, WIDTH, 3]
    with BagReader(synth_bags[0]) as reader:
        source_stamps = [msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec
                         for _, _, msg in reader.messages(['/camera/image_raw'])]
    data = pq.read_table(output / 'data/chunk-000/file-000.parquet').to_pydict()
    assert data['source.stamp_ns'] == source_stamps
    with BagReader(output / 'estimates/episode_000000') as reader:
        assert reader.topics()[HAND_FRAME_TOPIC].count == 6
        assert reader.topics()[MARKERS_TOPIC].count == 6
    reports = _report(output)
    assert [r['status'] for r in reports] == ['converted', 'converted']
    assert reports[0]['frames_in'] == 6 and reports[0]['frames_out'] == 6
    found = reports[0]['hands_found']  # every hand found is written or dropped for a reason
    assert found['found'] == found['written'] + sum(found['dropped'].values())
    # keyframe, ba_corrected, tracked, reinitialised, ba_failed, episode_refined
    flags = np.array(data['camera.flags'], dtype=bool)
    tracking = reports[0]['camera_tracking']
    first = flags[:6]
    assert tracking == {'tracked': int(first[:, 2].sum()),
                        'predicted': int((~first[:, 2] & ~first[:, 3]).sum()),
                        'reinitialised': int(first[:, 3].sum())}
    assert tracking['tracked'] >= 1  # the first frame at least: it defines the world
    assert not flags[:, 4].any() and reports[0]['ba_failed_frames'] == 0  # BA is off
    assert not flags[:, 5].any() and reports[0]['episode_refined_frames'] == 0


@pytest.mark.slow
def test_bad_inputs_fail_clearly_and_the_rest_converts(synth_bags: list[Path],
                                                       tmp_path: Path) -> None:
    """Garbage, no images, 16UC1 only, an empty bag and a missing path: exit 1, one episode."""
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'not a bag at all' * 10)
    depth = image_bag(tmp_path / 'depth', [(BASE_NS + k * PERIOD_NS, '16UC1',
                                            np.zeros((HEIGHT, WIDTH), np.uint16))
                                           for k in range(3)])
    no_images = image_bag(tmp_path / 'no_images', [], image_topic='/x')
    output = tmp_path / 'dataset'
    inputs = [garbage, depth, synth_bags[0], no_images, tmp_path / 'missing']
    assert _convert(inputs, output, tmp_path) == EXIT_FAILED
    errors = {Path(r['source']).name: r['error'] for r in _report(output)
              if r['status'] == 'failed'}
    assert set(errors) == {'garbage.mcap', 'depth', 'no_images', 'missing'}
    assert 'cannot be read' in errors['garbage.mcap']
    assert "3 x topic /camera/image_raw: image encoding '16UC1'" in errors['depth']
    assert 'no usable frame (0 image messages read)' in errors['no_images']
    assert errors['missing'] == 'does not exist'
    _check_dataset(output)
    assert _read_dataset(output)[0]['total_episodes'] == 1


@pytest.mark.slow
def test_stamp_and_size_problems_are_counted(tmp_path: Path) -> None:
    """bgr8 becomes RGB; duplicate, backward and resized frames are dropped and counted."""
    frames = [np.full((HEIGHT, WIDTH, 3), (200, 60 + k, 10), np.uint8) for k in range(6)]
    images = [(BASE_NS + k * PERIOD_NS, 'bgr8', np.ascontiguousarray(f[:, :, ::-1]))
              for k, f in enumerate(frames)]
    images.insert(3, (images[2][0], 'bgr8', frames[0]))  # duplicate stamp
    images.insert(5, (BASE_NS, 'bgr8', frames[0]))  # backwards
    images.append((BASE_NS + 9 * PERIOD_NS, 'rgb8', np.zeros((60, 80, 3), np.uint8)))
    bag = image_bag(tmp_path / 'bgr', images)
    output = tmp_path / 'dataset'
    assert _convert([bag], output, tmp_path) == EXIT_OK
    report = _report(output)[0]
    assert report['frames_in'] == 9 and report['frames_out'] == 6
    assert sorted(report['skipped'].values()) == [1, 1, 1]
    assert any('80x60 differs' in reason for reason in report['skipped'])
    with av.open(str(output / 'videos' / VIDEO_KEY / 'chunk-000/file-000.mp4')) as container:
        first = next(container.decode(video=0)).to_ndarray(format='rgb24')
    np.testing.assert_allclose(first.reshape(-1, 3).mean(axis=0), (200, 60, 10), atol=3)


@pytest.mark.slow
def test_resume_and_extend(synth_bags: list[Path], tmp_path: Path) -> None:
    """A re-run skips finished episodes; a later run appends with consistent indices."""
    output = tmp_path / 'dataset'
    assert _convert(synth_bags[:1], output, tmp_path) == EXIT_OK
    assert _convert(synth_bags, output, tmp_path) == EXIT_OK
    assert [r['status'] for r in _report(output)] == ['already in dataset', 'converted']
    _check_dataset(output)
    info, episodes = _read_dataset(output)
    assert info['total_episodes'] == 2 and episodes[1]['dataset_from_index'] == 6
    assert _convert(synth_bags, output, tmp_path, '--fps', '5') == EXIT_USAGE


@pytest.mark.slow
def test_disk_full_and_interrupt_keep_finished_episodes(
        synth_bags: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk fails one episode (exit 1); Ctrl-C exits 130; the dataset stays valid."""
    output = tmp_path / 'dataset'
    real_write = dataset_writer.atomic_write_bytes
    calls = []

    def full_disk(path: Path, data: bytes) -> None:
        if path.suffix == '.parquet':  # the second episode's data file
            calls.append(path)
            if len(calls) == 2:
                raise OSError(errno.ENOSPC, 'No space left on device')
        real_write(path, data)

    monkeypatch.setattr(dataset_writer, 'atomic_write_bytes', full_disk)
    assert _convert(synth_bags, output, tmp_path) == EXIT_FAILED
    assert 'No space left' in _report(output)[1]['error']
    _check_dataset(output)
    assert sorted(p.name for p in (output / 'data/chunk-000').iterdir()) == ['file-000.parquet']

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(run_module, 'convert_episode', interrupted)
    assert _convert(synth_bags, output, tmp_path) == EXIT_INTERRUPTED
    _check_dataset(output)
    assert _read_dataset(output)[0]['total_episodes'] == 1
    assert not [p for p in output.iterdir() if p.name.startswith('.')]


@pytest.mark.slow
def test_video_input(tmp_path: Path) -> None:
    """An mp4 with given intrinsics is one episode, resampled from 20 to 10 fps."""
    video = tmp_path / 'clip.mp4'
    writer = EpisodeVideoWriter(video, 20, VideoSettings())
    for frame in rgb_frames(8):
        writer.write(frame)
    writer.close()
    output = tmp_path / 'dataset'
    flags = ('--intrinsics', f'100,100,80,60,{WIDTH},{HEIGHT}', '--no-estimates-bag')
    assert _convert([video], output, tmp_path, *flags) == EXIT_OK
    _check_dataset(output)
    data = pq.read_table(output / 'data/chunk-000/file-000.parquet').to_pydict()
    assert data['source.stamp_ns'] == [0, 100_000_000, 200_000_000, 300_000_000]
    assert data['camera.intrinsics'][0] == [100, 100, 80, 60]


def test_distorted_video_records_its_lens(tmp_path: Path) -> None:
    """--intrinsics with --distortion: the episode record and the estimates bag carry the lens."""
    video = tmp_path / 'clip.mp4'
    writer = EpisodeVideoWriter(video, 10, VideoSettings())
    for frame in rgb_frames(3):
        writer.write(frame)
    writer.close()
    output = tmp_path / 'dataset'
    flags = ('--intrinsics', f'100,100,80,60,{WIDTH},{HEIGHT}',
             '--distortion', 'plumb_bob:-0.25,0.08,0,0,0.01')
    assert _convert([video], output, tmp_path, *flags) == EXIT_OK
    conversion = json.loads((output / 'meta/infinihand_conversion.json').read_text())
    assert conversion['episodes'][0]['lens'] == {
        'distortion_model': 'plumb_bob', 'distortion': [-0.25, 0.08, 0.0, 0.0, 0.01],
        'frames_distorted': 3}
    assert 'plumb_bob: -0.25, 0.08, 0, 0, 0.01' in (output / 'README.md').read_text()
    with BagReader(output / 'estimates/episode_000000') as reader:
        infos = [msg for _, _, msg in reader.messages([CAMERA_INFO_TOPIC])]
    assert len(infos) == 3
    assert infos[0].distortion_model == 'plumb_bob'
    np.testing.assert_allclose(infos[0].d, [-0.25, 0.08, 0.0, 0.0, 0.01])


@pytest.mark.slow
def test_truncated_bag_fails_clearly_and_the_rest_converts(synth_bags: list[Path],
                                                           tmp_path: Path) -> None:
    """A bag cut off mid-file (a crashed recorder) names itself; the good bag still converts."""
    truncated = tmp_path / 'truncated'
    shutil.copytree(synth_bags[0], truncated)
    for path in truncated.glob('*.mcap'):
        with path.open('r+b') as handle:
            handle.truncate(path.stat().st_size // 2)
    output = tmp_path / 'dataset'
    assert _convert([truncated, synth_bags[0]], output, tmp_path) == EXIT_FAILED
    errors = {Path(r['source']).name: r['error'] for r in _report(output)
              if r['status'] == 'failed'}
    assert set(errors) == {'truncated'} and 'cannot be read' in errors['truncated']
    assert _read_dataset(output)[0]['total_episodes'] == 1


@pytest.mark.parametrize('flags, message', [
    (('--distortion', 'plumb_bob:0.1,0,0,0,0'), '--distortion .* needs --intrinsics'),
    (('--intrinsics', '100,100,80,60,160,120', '--distortion', 'plumb_bob:0.1,0'),
     '--distortion: the plumb_bob model takes 5 coefficients'),
    (('--intrinsics', '100,100,80,60,160,120', '--distortion', 'fisheye:0.1,0,0,0'),
     "--distortion: distortion model 'fisheye' is not supported"),
    (('--intrinsics', '100,100,80,60,160,120', '--distortion', '0.1,0,0,0'),
     'expected MODEL:c1,c2'),
])
def test_distortion_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture,
                                 flags: tuple[str, ...], message: str) -> None:
    """A lens without intrinsics, a wrong count or an unknown model exit 2 with one line."""
    assert _convert([tmp_path], tmp_path / 'out', tmp_path, *flags) == EXIT_USAGE
    err = capsys.readouterr().err
    assert re.search(message, err), err


def test_unwritable_output_is_a_usage_error(synth_bags: list[Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture) -> None:
    assert _convert([synth_bags[0]], Path('/proc/no_dataset'), tmp_path) == EXIT_USAGE
    assert '--output /proc/no_dataset' in capsys.readouterr().err


def test_usage_errors(tmp_path: Path) -> None:
    """A directory that is not a dataset and malformed flags exit 2 before any conversion."""
    occupied = tmp_path / 'occupied'
    occupied.mkdir()
    (occupied / 'notes.txt').write_text('x')
    assert _convert([tmp_path], occupied, tmp_path) == EXIT_USAGE
    assert _convert([tmp_path], tmp_path / 'out', tmp_path, '--intrinsics', '1,2') == EXIT_USAGE
    assert _convert([tmp_path], tmp_path / 'out', tmp_path, '--fps', '0') == EXIT_USAGE


@pytest.mark.slow
def test_time_windows_with_bundle_adjustment(synth_bags: list[Path], tmp_path: Path) -> None:
    """--episode-seconds splits a bag into episodes; BA runs and reports its statistics.

    The dataset keeps the engine settings it was made with (the offline profile, --set last).
    """
    output = tmp_path / 'dataset'
    config = fast_config(tmp_path / 'ba.yaml', engine={})
    rc = main([str(synth_bags[0]), '--output', str(output), '--config', str(config), '--quiet',
               '--episode-seconds', '0.3', '--set', 'hands.min_confidence=0.6'])
    assert rc == EXIT_OK
    assert load_engine_config(output / 'engine_settings.yaml') == build_engine_config(
        'offline', ['hands.min_confidence=0.6'])
    reports = _report(output)
    assert [Path(r['source']).name for r in reports] == ['bag#0', 'bag#1']
    assert all(r['bundle_adjustment'] is not None for r in reports)
    _check_dataset(output)
    assert [e['length'] for e in _read_dataset(output)[1]] == [3, 3]


def test_conversion_waits_for_ba_instead_of_dropping(tmp_path: Path) -> None:
    """A conversion is offline: with BA on, every pool selection is refined (none dropped)."""
    with_ba = load_convert_config(fast_config(tmp_path / 'ba.yaml',
                                              engine={}))
    without = load_convert_config(fast_config(tmp_path / 'plain.yaml'))
    assert run_module.engine_config_for(with_ba).bundle_adjustment.worker.when_behind == 'wait'
    assert run_module.engine_config_for(without).bundle_adjustment is None


def test_the_dataset_holds_the_final_trajectory(synth_bags: list[Path], tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Every output frame's camera pose and BA failure are the ones ``refined`` returned.

    Frames 1 and 4 come back flagged ``ba_failed``: their ``camera.flags`` say so and the
    episode's report counts them.
    """
    refined_poses: list[np.ndarray] = []
    original = StreamingEngine.refined

    def shifted(engine: StreamingEngine, results: list, timeout_s: float | None = None) -> list:
        out = []
        for result in original(engine, results, timeout_s):
            pose = CameraPose(result.camera_pose.rotation,
                              result.camera_pose.translation + [1.0, 0.0, 0.0])
            refined_poses.append(pose.matrix())
            out.append(dataclasses.replace(result, camera_pose=pose,
                                           ba_failed=result.frame_index in (1, 4)))
        return out

    monkeypatch.setattr(StreamingEngine, 'refined', shifted)
    output = tmp_path / 'dataset'
    assert _convert([synth_bags[0]], output, tmp_path) == EXIT_OK
    info, episodes = _read_dataset(output)
    data = pq.read_table(output / info['data_path'].format(
        chunk_index=episodes[0]['data/chunk_index'], file_index=episodes[0]['data/file_index']))
    written = np.array(data.column(CAMERA_POSE).to_pylist()).reshape(-1, 4, 4)
    assert len(refined_poses) == len(written) == 6
    np.testing.assert_allclose(written, np.stack(refined_poses), atol=1e-6)
    flags = np.array(data.column(CAMERA_FLAGS).to_pylist(), dtype=bool)
    assert np.flatnonzero(flags[:, CAMERA_FLAG_NAMES.index('ba_failed')]).tolist() == [1, 4]
    assert _report(output)[0]['ba_failed_frames'] == 2
