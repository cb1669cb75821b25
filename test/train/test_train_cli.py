"""The ``train`` command: argument checks with one-line errors, a run and its resumption."""

from collections.abc import Callable
from pathlib import Path

from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.train.cli import build_parser
from infinihand_ros.train.cli import main
from infinihand_ros.train.cli import validate_args
from infinihand_ros.train.train_state import CHECKPOINTS_DIR
import pytest


def _validate(*argv: str):
    return validate_args(build_parser().parse_args(list(argv)))


def test_arguments_are_checked(write_run_config: Callable[..., Path], tmp_path: Path) -> None:
    config = str(write_run_config())
    with pytest.raises(InfiniHandError, match='give --config'):
        _validate('--output', str(tmp_path))
    with pytest.raises(InfiniHandError, match='--steps must be >= 1, got 0'):
        _validate('--config', config, '--output', str(tmp_path), '--steps', '0')
    with pytest.raises(InfiniHandError, match='give --output'):
        _validate('--config', config)
    with pytest.raises(InfiniHandError, match='--init .*: no such checkpoint'):
        _validate('--config', config, '--output', str(tmp_path), '--init', str(tmp_path / 'x'))
    with pytest.raises(InfiniHandError, match='neither a training checkpoint'):
        _validate('--resume', str(tmp_path))
    resolved, output = _validate('--config', config, '--output', str(tmp_path / 'o'),
                                 '--steps', '9', '--data', 'a', 'b')
    assert resolved.steps == 9 and resolved.data.sequences == ('a', 'b')
    assert output == tmp_path / 'o'


def test_run_resume_and_refusals(write_run_config: Callable[..., Path], tmp_path: Path,
                                 capsys: pytest.CaptureFixture) -> None:
    config = str(write_run_config(steps=2, checkpoint_every=1))
    output = str(tmp_path / 'run')
    assert main(['--config', config, '--output', output, '--stop-after', '1',
                 '--no-progress']) == 0
    assert 'trained steps 1..1 of 2' in capsys.readouterr().out
    assert main(['--config', config, '--output', output, '--no-progress']) == 2
    assert 'already holds a run' in capsys.readouterr().err
    checkpoint = tmp_path / 'run' / CHECKPOINTS_DIR / 'step_0000001'
    assert main(['--resume', str(checkpoint), '--no-progress']) == 0  # config + output from it
    assert 'trained steps 2..2 of 2' in capsys.readouterr().out
    assert main(['--resume', output, '--no-progress']) == 0
    assert 'nothing to do' in capsys.readouterr().out
    assert main(['--config', str(tmp_path / 'none.yaml'), '--output', output]) == 2
    error = capsys.readouterr().err
    assert error.startswith('error: ') and error.count('\n') == 1


def test_set_overrides_the_config_and_names_a_bad_key(write_run_config: Callable[..., Path],
                                                      tmp_path: Path) -> None:
    """``--set`` replaces values of --config (before --steps / --data); errors name the key."""
    config = str(write_run_config(steps=3))
    resolved, _ = _validate('--config', config, '--output', str(tmp_path / 'o'), '--set',
                            'train.seed=4', 'train.clip.clip_step=3', '--data', 'a',
                            '--set', 'losses.camera.weight=2.5')
    assert (resolved.seed, resolved.clip.clip_step, resolved.steps) == (4, 3, 3)
    assert resolved.losses.camera.weight == 2.5 and resolved.data.sequences == ('a',)
    with pytest.raises(InfiniHandError, match=r"train\.clip has no key 'stride'"):
        _validate('--config', config, '--output', str(tmp_path / 'o'), '--set',
                  'train.clip.stride=2')
