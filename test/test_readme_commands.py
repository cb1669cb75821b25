"""The README's commands work as typed after ``source scripts/env.sh`` (no ROS install needed).

Every command the README and the ``docs/`` pages show (in code blocks and inline code) that
starts with one of the package's console scripts, ``ros2 run infinihand_ros``,
``python -m infinihand_ros.`` or ``python benchmarks/`` is run with ``--help`` in a fresh bash
that only sourced the environment script, as a user would type it. Without ``ros2`` on PATH a
``ros2 run infinihand_ros X`` command is checked as the plain script ``X`` the README offers for
that setup. The nodes' ``--help`` also names their hand source and every parameter.
"""

import importlib.metadata
import os
from pathlib import Path
import re
import shutil
import subprocess

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
#: The pages whose commands are checked: the README and the reference pages it points to.
PAGES = [README, *sorted((ROOT / 'docs').glob('*.md'))]
PACKAGE = 'infinihand_ros'
ROS2_RUN = f'ros2 run {PACKAGE} '
_CODE = re.compile(r'```bash\n(.*?)```|`([^`\n][^`]*)`', re.DOTALL)


def console_scripts() -> set[str]:
    """Return the names of the package's console scripts."""
    return {entry.name for entry in importlib.metadata.entry_points(group='console_scripts')
            if entry.value.startswith(f'{PACKAGE}.')}


def readme_commands(text: str, scripts: set[str]) -> set[str]:
    """Return each distinct command the README shows, as the words before its arguments.

    Returns:
        e.g. {'bag_to_dataset', 'ros2 run infinihand_ros estimator',
        'python -m infinihand_ros.synth', 'python benchmarks/convert_speed.py'}.

    """
    pieces = []
    for block, inline in _CODE.findall(text):
        pieces += block.splitlines() if block else [inline]
    commands = set()
    for piece in pieces:
        words = ' '.join(piece.replace('\\\n', ' ').split()).split(' ')
        if words[:3] == ROS2_RUN.split():
            commands.add(' '.join(words[:4]))
        elif words[:2] == ['python', '-m'] and words[2:3] and words[2].startswith(PACKAGE):
            commands.add(' '.join(words[:3]))
        elif words[:1] == ['python'] and words[1:2] and words[1].startswith('benchmarks/'):
            commands.add(' '.join(words[:2]))
        elif words[0] in scripts:
            commands.add(words[0])
    return commands


def _as_typed(command: str) -> str:
    """Return the command to run here: ``ros2 run`` only where a ROS install provides it."""
    if command.startswith(ROS2_RUN) and shutil.which('ros2') is None:
        return command[len(ROS2_RUN):]
    return command


def _fresh_bash(line: str) -> subprocess.CompletedProcess:
    """Run ``line`` in a new bash that sourced only scripts/env.sh (no venv on PATH before)."""
    env = {'HOME': os.environ.get('HOME', '/tmp'), 'PATH': '/usr/local/bin:/usr/bin:/bin',
           'LANG': 'C.UTF-8'}
    return subprocess.run(['bash', '-c', f'source scripts/env.sh && {line}'], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=180)


def _commands() -> list[str]:
    return sorted(set().union(*(readme_commands(page.read_text(encoding='utf-8'),
                                                console_scripts()) for page in PAGES)))


def test_readme_commands_are_found() -> None:
    """The README shows the converter and the nodes; each script it names resolves on PATH."""
    commands = _commands()
    assert 'bag_to_dataset' in commands and f'{ROS2_RUN}estimator' in commands
    words = [_as_typed(c) for c in commands if ' ' not in _as_typed(c)]
    result = _fresh_bash(' && '.join(f'command -v {word}' for word in words))
    assert result.returncode == 0, result.stderr
    assert all('/install/infinihand_ros/lib/infinihand_ros/' in line
               for line in result.stdout.splitlines())


def test_extraction_reads_blocks_and_inline_code() -> None:
    """Commands come out of bash blocks, wrapped inline code and ros2 run lines."""
    text = ('```bash\nbag_to_dataset IN --output OUT \\\n    [--fps 10]\n```\n'
            'then `python -m\ninfinihand_ros.synth.batch --out DIR` and `train.box_jitter`, '
            '`ros2 run infinihand_ros replay x` or `python benchmarks/a.py`.')
    assert readme_commands(text, {'bag_to_dataset', 'train', 'replay'}) == {
        'bag_to_dataset', 'python -m infinihand_ros.synth.batch',
        f'{ROS2_RUN}replay', 'python benchmarks/a.py'}


@pytest.mark.slow
@pytest.mark.parametrize('command', _commands())
def test_readme_command_help(command: str) -> None:
    """``COMMAND --help`` exits 0 with a usage line, as typed after source scripts/env.sh."""
    result = _fresh_bash(f'{_as_typed(command)} --help')
    assert result.returncode == 0, f'{command} --help: {result.stderr[-2000:]}'
    assert 'usage' in result.stdout.lower(), result.stdout[:500]


def test_node_help_names_the_hand_source_and_the_parameters() -> None:
    """``estimator --help`` says which hand source runs and why, and lists its parameters."""
    result = _fresh_bash('estimator --help')
    assert result.returncode == 0, result.stderr[-2000:]
    assert 'mediapipe by default' in result.stdout and 'synthetic' in result.stdout
    assert "hands.source ('mediapipe')" in result.stdout
    assert "engine.bundle_adjustment ('none')" in result.stdout
