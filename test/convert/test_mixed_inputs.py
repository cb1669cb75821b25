"""Inputs of different sizes and rates into one dataset, with provenance (convert/cli.py)."""

import json
from pathlib import Path

import av
from convert_builders import BASE_NS
from convert_builders import fast_config
from convert_builders import image_bag
from convert_builders import PERIOD_NS
from infinihand_ros.convert import dataset_card
from infinihand_ros.convert.cli import EXIT_OK
from infinihand_ros.convert.cli import EXIT_USAGE
from infinihand_ros.convert.cli import main
from infinihand_ros.convert.dataset_card import CARD_FILE
from infinihand_ros.convert.lerobot_features import HAND_CONFIDENCE
from infinihand_ros.convert.lerobot_features import INTRINSICS
from infinihand_ros.convert.lerobot_layout import CONVERSION_PATH
from infinihand_ros.convert.provenance import files_sha256
from infinihand_ros.model.io.bundled import resolve_checkpoint
import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

VIDEO = 'videos/observation.images.ego/chunk-000/file-{:03d}.mp4'
DATA = 'data/chunk-000/file-{:03d}.parquet'


def _bag(path: Path, size: tuple[int, int], count: int, period_ns: int, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    images = [(BASE_NS + k * period_ns, 'rgb8',
               rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8))
              for k in range(count)]
    return image_bag(path, images)


def _convert(inputs: list[Path], output: Path, tmp_path: Path, *flags: str) -> int:
    config = fast_config(tmp_path / 'convert.yaml')
    return main([*map(str, inputs), '--output', str(output), '--config', str(config), '--quiet',
                 '--no-estimates-bag', *flags])


def _video_size(path: Path) -> tuple[int, int]:
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return stream.width, stream.height


@pytest.mark.slow
def test_sizes_and_rates_mix_into_one_dataset(tmp_path: Path) -> None:
    # 160x120 at 10 Hz, then 200x100 at 25 Hz: the second is letterboxed to 160x120 (scale 0.8,
    # 20 black rows above and below) and resampled to 10 Hz.
    first = _bag(tmp_path / 'first', (160, 120), 6, PERIOD_NS, 1)
    second = _bag(tmp_path / 'second', (200, 100), 15, PERIOD_NS * 2 // 5, 2)
    output = tmp_path / 'dataset'
    assert _convert([first, second], output, tmp_path) == EXIT_OK
    info = json.loads((output / 'meta/info.json').read_text())
    assert info['features']['observation.images.ego']['shape'] == [120, 160, 3]
    assert [_video_size(output / VIDEO.format(k)) for k in range(2)] == [(160, 120)] * 2
    records = json.loads((output / CONVERSION_PATH).read_text())['episodes']
    assert records[0]['image']['mode'] == 'none'
    image = records[1]['image']
    assert image['mode'] == 'letterbox' and image['source_size'] == [200, 100]
    assert image['scale'] == [0.8, 0.8] and image['content_box'] == [0, 20, 160, 100]
    # CameraInfo of the second bag (fx 100, centre 100,50) mapped to the dataset's pixels.
    data = pq.read_table(output / DATA.format(1)).to_pydict()
    assert len(data[INTRINSICS]) == 6  # 0.56 s at 10 Hz
    np.testing.assert_allclose(np.array(data[INTRINSICS]),
                               [[80.0, 80.0, 79.9, 59.9]] * 6, atol=1e-4)
    assert all(0.0 <= c <= 1.0 for row in data[HAND_CONFIDENCE] for c in row)
    provenance = records[1]['provenance']
    assert provenance == records[0]['provenance']
    assert provenance['hand_source'] == 'mediapipe'  # the converter's default
    assert provenance['weights'] == {'full': {
        'name': 'tiny_synthetic', 'sha256': files_sha256(resolve_checkpoint('tiny_synthetic'))}}
    assert len(provenance['engine_config_sha256']) == 64 and provenance['package_version']
    # The dataset's size stays: a third input with --video-size of another size is refused.
    assert _convert([first], output, tmp_path, '--video-size', '200x100') == EXIT_USAGE


@pytest.mark.slow
def test_video_size_flag_and_crop(tmp_path: Path) -> None:
    small = _bag(tmp_path / 'small', (160, 120), 4, PERIOD_NS, 3)
    output = tmp_path / 'dataset'
    assert _convert([small], output, tmp_path, '--video-size', '320x180', '--resize',
                    'crop') == EXIT_OK
    assert _video_size(output / VIDEO.format(0)) == (320, 180)
    image = json.loads((output / CONVERSION_PATH).read_text())['episodes'][0]['image']
    # 160x120 scaled by 2 to cover 320x180: 320x240, 30 rows cut above and below.
    assert image['mode'] == 'crop' and image['scale'] == [2.0, 2.0]
    np.testing.assert_allclose(image['offset'], [0.5, -29.5])
    data = pq.read_table(output / DATA.format(0)).to_pydict()
    np.testing.assert_allclose(np.array(data[INTRINSICS])[0], [200.0, 200.0, 160.5, 90.5],
                               atol=1e-4)


@pytest.mark.slow
def test_card_is_written_and_follows_the_dataset(tmp_path: Path) -> None:
    first = _bag(tmp_path / 'first', (160, 120), 4, PERIOD_NS, 4)
    second = _bag(tmp_path / 'second', (160, 120), 3, PERIOD_NS, 5)
    output = tmp_path / 'dataset'
    assert _convert([first], output, tmp_path) == EXIT_OK
    card = (output / CARD_FILE).read_text()
    header = yaml.safe_load(card.split('---\n')[1])
    assert header['license'] is None and header['task_categories'] == ['robotics']
    assert 'LeRobot' in header['tags']
    assert '1 episodes, 4 frames at 10 fps' in card
    assert f'| `{INTRINSICS}` | float32 | [4] | px |' in card
    assert 'From the card of the model `tiny_synthetic`' in card and 'Synthetic only' in card
    # A card left stale (a run stopped between meta/ and the card) is rewritten on open.
    (output / CARD_FILE).write_text('stale')
    assert _convert([first], output, tmp_path) == EXIT_OK  # nothing to add
    assert (output / CARD_FILE).read_text() == card
    assert _convert([first, second], output, tmp_path) == EXIT_OK
    card = (output / CARD_FILE).read_text()
    assert '2 episodes, 7 frames at 10 fps' in card and str(second) in card
    assert not list(output.glob(f'.{CARD_FILE}.*'))


def test_card_says_what_mediapipe_hands_lack() -> None:
    """Episodes with MediaPipe hands: the card says their shape is the mean one; else not."""
    said = 'Episodes whose hands come from MediaPipe'
    mediapipe = [{'provenance': {'hand_source': 'mediapipe', 'weights': {}}}]
    branch = [{'provenance': {'hand_source': 'infinihand', 'weights': {}}}]
    assert any(said in line for line in dataset_card._limitations(mediapipe + branch))
    assert not any(said in line for line in dataset_card._limitations(branch))
