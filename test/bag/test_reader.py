"""BagReader: topics and messages of good bags, one clear BagError for every kind of broken bag."""

from pathlib import Path
import shutil

from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core import topics
from infinihand_ros.core.errors import BagError
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import pytest


@pytest.fixture(scope='module')
def small_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Write a three-frame synthetic bag and return its path."""
    path = tmp_path_factory.mktemp('bags') / 'bag'
    with BagSink(path) as sink:
        for frame in SyntheticSequence(SynthConfig(width=64, height=48), seed=3, num_frames=3):
            sink.add(frame)
    return path


def test_topics_duration_and_messages(small_bag: Path) -> None:
    with BagReader(small_bag) as reader:
        assert reader.topics()[topics.IMAGE_TOPIC].count == 3
        assert reader.topics()[topics.IMAGE_TOPIC].msgtype == 'sensor_msgs/msg/Image'
        assert reader.duration_s() == pytest.approx(0.2)
        stamps = [stamp for _, stamp, _ in reader.messages([topics.CAMERA_INFO_TOPIC])]
    assert stamps == sorted(stamps) and len(stamps) == 3


def test_missing_topic_names_the_topics_there_are(small_bag: Path) -> None:
    with BagReader(small_bag) as reader:
        with pytest.raises(BagError, match=r"no topic\(s\) \['/nope'\]; it has \['/camera"):
            list(reader.messages(['/nope']))


def _break_bag(small_bag: Path, target: Path, how: str) -> Path:
    shutil.copytree(small_bag, target)
    data_file = next(target.glob('*.mcap'))
    if how == 'truncated':
        data_file.write_bytes(data_file.read_bytes()[:data_file.stat().st_size // 2])
    elif how == 'garbage':
        data_file.write_bytes(b'not an mcap file' * 64)
    elif how == 'no metadata':
        (target / 'metadata.yaml').unlink()
    return target


@pytest.mark.parametrize('how', ['truncated', 'garbage', 'no metadata'])
def test_broken_bags_raise_bag_error(small_bag: Path, tmp_path: Path, how: str) -> None:
    broken = _break_bag(small_bag, tmp_path / 'broken', how)
    with pytest.raises(BagError, match=f'bag {broken} '):
        with BagReader(broken) as reader:
            list(reader.messages([topics.CAMERA_INFO_TOPIC]))


def test_missing_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='does not exist; pass a rosbag2 directory'):
        with BagReader(tmp_path / 'none'):
            pass
