"""Tests of infinihand_ros/convert/inputs.py: bags, split files, folders, videos, failures."""

from pathlib import Path

from infinihand_ros.convert.inputs import BAG
from infinihand_ros.convert.inputs import discover_inputs
from infinihand_ros.convert.inputs import IMAGES
from infinihand_ros.convert.inputs import VIDEO


def _bag_dir(path: Path, *files: str) -> Path:
    path.mkdir(parents=True)
    (path / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    for name in files:
        (path / name).write_bytes(b'')
    return path


def test_folders_split_files_and_videos(tmp_path: Path) -> None:
    """A folder yields its bags (not their split files), bare files and videos, sorted."""
    split = _bag_dir(tmp_path / 'data' / 'b_split', 'b_0.mcap', 'b_1.mcap')
    sqlite = _bag_dir(tmp_path / 'data' / 'a_sqlite', 'a_0.db3')
    (tmp_path / 'data' / 'nested').mkdir()
    bare = tmp_path / 'data' / 'nested' / 'c.mcap'
    bare.write_bytes(b'')
    video = tmp_path / 'data' / 'nested' / 'd.MP4'
    video.write_bytes(b'')
    (tmp_path / 'data' / 'notes.txt').write_text('x')
    sources, failures = discover_inputs([tmp_path / 'data', split / 'b_1.mcap'])
    assert failures == []
    assert [(s.path, s.kind) for s in sources] == [
        (sqlite, BAG), (split, BAG), (bare, BAG), (video, VIDEO)]


def test_failures_name_path_and_reason(tmp_path: Path) -> None:
    """Missing paths, empty folders and unknown files are failures with a reason."""
    (tmp_path / 'empty').mkdir()
    (tmp_path / 'x.txt').write_text('x')
    sources, failures = discover_inputs(
        [tmp_path / 'missing', tmp_path / 'empty', tmp_path / 'x.txt'])
    assert sources == []
    reasons = {f.path.name: f.reason for f in failures}
    assert reasons['missing'] == 'does not exist'
    assert 'holds no rosbag2 bag' in reasons['empty']
    assert 'not a bag' in reasons['x.txt']


def test_image_sequences_and_gifs(tmp_path: Path) -> None:
    """A folder with images directly inside is one episode; its subfolders are still searched."""
    frames = tmp_path / 'rgb_frames' / 'P01_01'
    frames.mkdir(parents=True)
    for name in ('frame_0000000002.jpg', 'frame_0000000001.JPG'):
        (frames / name).write_bytes(b'')
    nested = frames / 'takes'
    nested.mkdir()
    (nested / 'a.png').write_bytes(b'')
    gif = tmp_path / 'rgb_frames' / 'clip.gif'
    gif.write_bytes(b'')
    sources, failures = discover_inputs([tmp_path / 'rgb_frames'])
    assert failures == []
    assert [(s.path, s.kind) for s in sources] == [
        (frames, IMAGES), (nested, IMAGES), (gif, VIDEO)]
    assert [(s.path, s.kind) for s in discover_inputs([frames])[0]] == [
        (frames, IMAGES), (nested, IMAGES)]
