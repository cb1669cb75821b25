"""Argument checks of the replay and record commands (tools/replay.py, tools/record.py)."""

from pathlib import Path

from live_processes import SAMPLE_BAG
import pytest

record_cli = pytest.importorskip('infinihand_ros.tools.record', reason='needs rclpy')
replay_cli = pytest.importorskip('infinihand_ros.tools.replay', reason='needs rclpy')

pytestmark = pytest.mark.ros


def test_replay_options() -> None:
    """Rate, clock, loop, topics and remaps are parsed."""
    options = replay_cli.parse_args([str(SAMPLE_BAG), '--rate', '0', '--clock', '--loop',
                                     '--topics', '/a', '--remap', '/a:=/b'])
    assert (options.rate, options.clock, options.loop) == (0.0, True, True)
    assert options.topics == ('/a',) and options.remap == {'/a': '/b'}
    options = replay_cli.parse_args([str(SAMPLE_BAG), '--delay', '1.5',
                                     '--playback-duration', '4'])
    assert (options.delay_s, options.duration_s) == (1.5, 4.0)


@pytest.mark.parametrize('args,message', [
    (['--rate', '-1'], '--rate must be >= 0'),
    (['--remap', '/a=/b'], 'write OLD:=NEW'),
    (['--delay', '-1'], '--delay must be >= 0'),
    (['--playback-duration', 'nan'], '--playback-duration must be >= 0'),
])
def test_replay_bad_arguments_exit_2(args: list[str], message: str,
                                     capsys: pytest.CaptureFixture) -> None:
    """Bad arguments exit 2 with a line naming them."""
    with pytest.raises(SystemExit) as done:
        replay_cli.parse_args([str(SAMPLE_BAG), *args])
    assert done.value.code == 2 and message in capsys.readouterr().err


def test_replay_needs_a_bag_directory(capsys: pytest.CaptureFixture) -> None:
    """A missing bag exits 2."""
    with pytest.raises(SystemExit):
        replay_cli.parse_args(['/no/such/bag'])
    assert 'not a directory' in capsys.readouterr().err


def test_message_class_resolves_importable_types_only() -> None:
    """Standard and generated types import; a package that does not exist gives None."""
    assert replay_cli.message_class('sensor_msgs/msg/CompressedImage').__name__ == (
        'CompressedImage')
    assert replay_cli.message_class('no_such_msgs/msg/Thing') is None
    pytest.importorskip('infinihand_msgs.msg', reason='infinihand_msgs is not built (make)')
    assert replay_cli.message_class('infinihand_msgs/msg/HandFrame').__name__ == 'HandFrame'


def test_record_arguments(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """An existing output or a relative topic exits 2; good ones parse."""
    options = record_cli.parse_args(['-o', str(tmp_path / 'new'), '/a', '/b', '/a'])
    assert options.topics == ('/a', '/b')
    with pytest.raises(SystemExit):
        record_cli.parse_args(['-o', str(tmp_path), '/a'])
    assert 'exists' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        record_cli.parse_args(['-o', str(tmp_path / 'x'), 'relative'])
    assert 'must be absolute' in capsys.readouterr().err
