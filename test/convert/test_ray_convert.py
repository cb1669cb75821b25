"""Shards and ``bag_to_dataset --ray`` (convert/shard.py, convert/ray_run.py)."""

import json
import os
from pathlib import Path
import sys

import av
from convert_builders import fast_config
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.convert.cli import EXIT_FAILED
from infinihand_ros.convert.cli import EXIT_OK
from infinihand_ros.convert.cli import EXIT_USAGE
from infinihand_ros.convert.cli import main
from infinihand_ros.convert.cli import REPORT_FILE
from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.config import RaySettings
from infinihand_ros.convert.dataset_writer import DatasetWriter
from infinihand_ros.convert.inputs import BAG
from infinihand_ros.convert.inputs import discover_inputs
from infinihand_ros.convert.inputs import InputSource
from infinihand_ros.convert.ray_run import failure_report
from infinihand_ros.convert.ray_run import plan_workers
from infinihand_ros.convert.ray_run import results_in_order
from infinihand_ros.convert.report import EpisodeReport
from infinihand_ros.convert.run import RunOptions
from infinihand_ros.convert.shard import merge_shard
from infinihand_ros.convert.shard import ShardConverter
import numpy as np
import pyarrow.parquet as pq
import pytest

VIDEO = 'videos/observation.images.ego/chunk-000'
#: Fields of a report that depend on the machine's timing, not on the conversion.
TIMING = ('seconds', 'frames_per_s')


def _dataset(root: Path) -> dict:
    """Return everything a dataset holds that must not depend on how it was converted."""
    episodes = pq.read_table(root / 'meta/episodes/chunk-000/file-000.parquet').to_pylist()
    conversion = json.loads((root / 'meta/infinihand_conversion.json').read_text())
    frames = []
    for path in sorted((root / VIDEO).iterdir()):
        with av.open(str(path)) as container:
            frames.append([frame.time for frame in container.decode(video=0)])
    estimates = []
    for path in sorted((root / 'estimates').iterdir()):
        with BagReader(path) as reader:
            estimates.append({name: topic.count for name, topic in reader.topics().items()})
    return {
        'info': json.loads((root / 'meta/info.json').read_text()),
        'stats': json.loads((root / 'meta/stats.json').read_text()),
        'tasks': pq.read_table(root / 'meta/tasks.parquet').to_pylist(),
        'episodes': episodes,
        'sources': [record['source'] for record in conversion['episodes']],
        'data': [pq.read_table(path).to_pydict()
                 for path in sorted((root / 'data/chunk-000').iterdir())],
        'video_times': frames, 'estimates': estimates}


def _assert_same(actual: object, expected: object) -> None:
    """Equal structure and values (floats within 1e-5)."""
    if isinstance(expected, dict):
        assert sorted(actual) == sorted(expected)
        for key in expected:
            _assert_same(actual[key], expected[key])
    elif isinstance(expected, list) and expected and isinstance(expected[0], (dict, list)):
        assert len(actual) == len(expected)
        for got, want in zip(actual, expected):
            _assert_same(got, want)
    elif isinstance(expected, list) and expected and isinstance(expected[0], float):
        np.testing.assert_allclose(actual, expected, rtol=1e-5, atol=1e-6)
    else:
        assert actual == expected


def _reports(root: Path) -> list[dict]:
    reports = json.loads((root / REPORT_FILE).read_text())
    return [{k: v for k, v in r.items() if k not in TIMING} for r in reports]


def test_workers_follow_the_cluster() -> None:
    """One actor per GPU (or per CPU without GPUs), never more than the inputs, at least one."""
    settings = RaySettings()
    gpu = plan_workers(settings, {'CPU': 32.0, 'GPU': 4.0}, 10)
    assert (gpu.workers, gpu.num_cpus, gpu.num_gpus) == (4, 1.0, 1.0)
    cpu = plan_workers(RaySettings(cpus_per_worker=2.0), {'CPU': 7.0}, 10)
    assert (cpu.workers, cpu.num_gpus) == (3, 0.0)
    assert plan_workers(settings, {'CPU': 16.0}, 2).workers == 2
    assert plan_workers(RaySettings(workers=5), {'CPU': 1.0}, 8).workers == 5
    assert plan_workers(settings, {'CPU': 0.5}, 3).workers == 1


def test_ray_missing_is_a_usage_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture) -> None:
    """Without Ray, --ray exits 2 before converting anything and says how to install it."""
    monkeypatch.setitem(sys.modules, 'ray', None)  # import ray raises ImportError
    bag = tmp_path / 'in.mcap'
    bag.write_bytes(b'x')
    output = tmp_path / 'dataset'
    assert main([str(bag), '--output', str(output), '--quiet', '--ray']) == EXIT_USAGE
    assert 'Ray, which is not installed' in capsys.readouterr().err
    assert not (output / 'meta').exists()


@pytest.mark.slow
def test_shards_merge_into_the_local_dataset(synth_bags: list[Path], tmp_path: Path) -> None:
    """Inputs converted into shards and merged give the local run's dataset and reports."""
    config_path = fast_config(tmp_path / 'convert.yaml')
    local = tmp_path / 'local'
    assert main([*map(str, synth_bags), '--output', str(local), '--config', str(config_path),
                 '--quiet']) == EXIT_OK
    merged = tmp_path / 'merged'
    config = load_convert_config(config_path)
    writer = DatasetWriter(merged, config)
    converter = ShardConverter(config, RunOptions(merged, progress=False))
    sources, _ = discover_inputs(synth_bags)
    shards = [converter.convert(source, tmp_path / f'shard{k}', set())
              for k, source in enumerate(sources)]
    converter.close()
    reports: list[EpisodeReport] = []
    for shard in reversed(shards):  # merge order sets the numbering, not conversion order
        merge_shard(writer, shard, reports)
    assert [r.episode_index for r in reports] == [0, 1]
    assert [Path(r.source).parent.name for r in reports] == ['jpeg', 'raw']
    assert not [p for p in (tmp_path / 'shard0').rglob('*') if p.is_file()]  # all moved
    local_data = _dataset(local)
    merged_data = _dataset(merged)
    assert merged_data['sources'] == local_data['sources'][::-1]
    _assert_same(merged_data['data'][0]['observation.state'],
                 local_data['data'][1]['observation.state'])


@pytest.fixture()
def local_ray() -> object:
    """Start a 2-CPU local Ray instance for one test."""
    ray = pytest.importorskip('ray')
    ray.init(num_cpus=2, include_dashboard=False, configure_logging=False)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_ray_gives_the_local_dataset(synth_bags: list[Path], tmp_path: Path,
                                     local_ray: object) -> None:
    """Two actors: same episodes in input order, same values, same reports, same resume."""
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'not a bag at all' * 10)
    inputs = [str(synth_bags[0]), str(garbage), str(synth_bags[1])]
    config = str(fast_config(tmp_path / 'convert.yaml', ray={'workers': 2}))
    outputs = {mode: tmp_path / mode for mode in ('local', 'ray')}
    for mode, flags in (('local', []), ('ray', ['--ray'])):
        assert main([*inputs, '--output', str(outputs[mode]), '--config', config, '--quiet',
                     *flags]) == EXIT_FAILED
    expected = _dataset(outputs['local'])
    assert len(expected['episodes']) == 2
    _assert_same(_dataset(outputs['ray']), expected)
    _assert_same(_reports(outputs['ray']), _reports(outputs['local']))
    assert [r['status'] for r in _reports(outputs['ray'])] == ['converted', 'failed',
                                                               'converted']
    assert not [p for p in outputs['ray'].iterdir() if p.name.startswith('.')]
    assert main([*inputs, '--output', str(outputs['ray']), '--config', config, '--quiet',
                 '--ray']) == EXIT_FAILED
    statuses = [r['status'] for r in _reports(outputs['ray'])]
    assert statuses == ['already in dataset', 'failed', 'already in dataset']


@pytest.mark.slow
def test_worker_failures_come_back_in_order(local_ray: object) -> None:
    """A crashed actor is replaced, a raising call is reported, the order is the calls'."""
    class Flaky:
        def convert(self, name: str) -> str:
            if name == 'crash':
                os._exit(1)
            if name == 'raise':
                raise RuntimeError('boom')
            return name

        def close(self) -> None:
            pass

    actor_class = local_ray.remote(Flaky).options(num_cpus=1)
    calls = [('a',), ('crash',), ('raise',), ('b',), ('c',)]
    results = list(results_in_order(local_ray, actor_class.remote, 2, calls))
    assert (results[0], results[3], results[4]) == ('a', 'b', 'c')
    assert isinstance(results[1], local_ray.exceptions.RayActorError)
    report = failure_report(InputSource(Path('in.mcap'), BAG), results[2])
    assert (report.source, report.status) == ('in.mcap', 'failed')
    assert report.error == 'the Ray worker failed: RuntimeError: boom'
