"""The engine's settings: named profiles, ``--set`` overrides and the generated engine YAML.

Every setting is declared once, in the engine's dataclasses (``engine/config.py`` and the section
classes it nests): its default, and its description (the field's ``parameter`` spec, else the
class docstring's ``Attributes`` entry). The defaults are the ``live`` profile: real camera
images from a moving camera, answered frame by frame. What differs between uses is a named
profile (``PROFILES``), a few dotted keys each; an entry point names its profile, and every
command line takes ``--set key=value`` overrides on top. ``build_engine_config`` is the one
function that resolves them: defaults, then the profile, then a settings file, then the
overrides. ``config/engine.yaml`` is generated from the dataclasses
(``python -m infinihand_ros.engine.settings --write``; a test fails when it drifts), and every
output saves the settings it ran with (``save_engine_settings``).
"""

import argparse
from collections.abc import Iterable
from collections.abc import Mapping
import copy
import dataclasses
from pathlib import Path
import re
import shlex
import sys
import textwrap
import typing
from typing import Any, Final

from infinihand_ros.ba.config import BA_SECTION
from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import config_to_dict
from infinihand_ros.core.config import read_yaml
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import ENGINE_SECTION
from infinihand_ros.engine.config import EngineConfig
import yaml

#: Bundle adjustment as an offline run wants it: every pool selection refined (the stream waits).
OFFLINE_BA: Final[dict[str, Any]] = {'bundle_adjustment': True,
                                     'bundle_adjustment.worker.when_behind': 'wait',
                                     'bundle_adjustment.episode.enabled': True}
#: What each use changes from the defaults (which are ``live``'s), as dotted keys.
PROFILES: Final[dict[str, dict[str, Any]]] = {
    'live': {},
    'teleop': {'camera_motion': 'static', 'hands.egocentric': False},
    'offline': {'mode': 'windowed', 'lens_warmup': 'first', 'hands.ray_passes': 8,
                **OFFLINE_BA},
    'synthetic': {'hands.source': 'infinihand'},
}
PROFILE_HELP: Final = {
    'live': 'a moving camera, real images, each frame answered as it comes (the defaults; the '
            'node and the Python API)',
    'teleop': 'a fixed camera (tripod, robot-mounted): its pose is the world frame',
    'offline': 'recordings converted as a whole (bag_to_dataset): windowed, with bundle '
               'adjustment',
    'synthetic': "our synthetic data (the demo, the evaluation): the paper's hand branch, "
                 'whose bundled weights have seen only synthetic images',
}
DEFAULT_PROFILE: Final = 'live'
SETTINGS_FILE: Final = 'engine_settings.yaml'
ENGINE_YAML: Final = 'engine.yaml'
_LINE_WIDTH: Final = 99
_KEY = re.compile(r'^[a-z_][a-z0-9_]*(\.[a-z_][a-z0-9_]*)*$')


def parse_overrides(items: Iterable[str], where: str = '--set') -> dict[str, Any]:
    """Return ``key=value`` strings as dotted key -> value (values read as YAML scalars/lists).

    Raises:
        ConfigError: naming ``where`` for an item without ``=`` or with a malformed key.

    """
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition('=')
        key = key.strip()
        if not sep or not _KEY.match(key):
            raise ConfigError(f'{where}: {item!r} is not key=value with a dotted setting name '
                              '(for example geometry_interval=1 or hands.source=mediapipe)')
        try:
            overrides[key] = yaml.safe_load(text) if text.strip() else ''
        except yaml.YAMLError as exc:
            raise ConfigError(f'{where}: the value of {key!r} is not valid YAML ({exc})') from exc
    return overrides


def split_overrides(text: str, where: str) -> dict[str, Any]:
    """Return the overrides in a string of space-separated ``key=value`` pairs (shell quoting)."""
    try:
        items = shlex.split(text)
    except ValueError as exc:
        raise ConfigError(f'{where}: {text!r} cannot be split into key=value pairs ({exc})') \
            from exc
    return parse_overrides(items, where)


def checkpoint_overrides(checkpoint: str) -> dict[str, Any]:
    """Return the overrides that make ``checkpoint`` (a whole model) the engine's model."""
    return {'model.checkpoint': checkpoint, 'model.geometry_weights': None,
            'model.crop_encoder_weights': None}


def build_engine_config(profile: str = DEFAULT_PROFILE,
                        overrides: Mapping[str, Any] | Iterable[str] = (),
                        config_file: str | Path | None = None) -> EngineConfig:
    """Return the engine settings of ``profile``, a settings file and overrides, checked.

    Args:
        profile: a name in ``PROFILES``.
        overrides: dotted key -> value, or ``key=value`` strings (``--set``); applied last.
        config_file: an engine YAML (``config/engine.yaml`` layout; any subset of its keys),
            applied between the profile and the overrides.

    Raises:
        ConfigError: for an unknown profile, file or key, or a rejected value (naming it).

    """
    if profile not in PROFILES:
        raise ConfigError(f'profile {profile!r} is not one of {list(PROFILES)}')
    if not isinstance(overrides, Mapping):
        overrides = parse_overrides(overrides)
    data = config_to_dict(EngineConfig())
    _apply(data, PROFILES[profile], f'profile {profile}')
    where = f'profile {profile}'
    if config_file is not None:
        section = _file_section(Path(config_file).expanduser())
        _merge(data, _resolved_ba(section, str(config_file)))
        where += f' + {config_file}'
    _apply(data, overrides, '--set')
    try:
        return config_from_dict(EngineConfig, data, ENGINE_SECTION)
    except ConfigError as exc:
        raise ConfigError(f'engine settings of {where}: {exc}') from exc


def load_engine_config(path: str | Path | None = None) -> EngineConfig:
    """Return the defaults with the engine YAML ``path`` applied (the package's when None).

    Raises:
        ConfigError: for a missing or unreadable file, unknown keys, wrong types or values
            (naming the key).

    """
    path = Path(path) if path is not None else config_dir() / ENGINE_YAML
    return build_engine_config(DEFAULT_PROFILE, {}, path)


def _file_section(path: Path) -> dict[str, Any]:
    """Return the ``engine`` section of a settings file."""
    data = read_yaml(path)
    if not isinstance(data, dict) or ENGINE_SECTION not in data:
        raise ConfigError(f'{path}: no {ENGINE_SECTION!r} section')
    section = data[ENGINE_SECTION] or {}
    if not isinstance(section, dict):
        raise ConfigError(f'{path}: {ENGINE_SECTION} must be a mapping of settings')
    return dict(section)


def _resolved_ba(section: dict[str, Any], where: str) -> dict[str, Any]:
    """Return ``section`` with ``bundle_adjustment: true`` / a path replaced by its settings."""
    ba = section.get('bundle_adjustment')
    if ba is True or isinstance(ba, str):
        ba_path = config_dir() / 'ba.yaml' if ba is True else Path(ba).expanduser()
        ba_data = read_yaml(ba_path)
        if not isinstance(ba_data, dict) or BA_SECTION not in ba_data:
            raise ConfigError(f'{where}: bundle_adjustment: {ba_path} has no {BA_SECTION!r} '
                              'section')
        section = {**section, 'bundle_adjustment': ba_data[BA_SECTION] or {}}
    elif ba is False:
        section = {**section, 'bundle_adjustment': None}
    return section


def _merge(data: dict[str, Any], section: Mapping[str, Any]) -> None:
    """Merge a nested mapping into ``data``: mappings into mappings, anything else replaces."""
    for key, value in section.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            _merge(data[key], value)
        else:
            data[key] = copy.deepcopy(value)


def _apply(data: dict[str, Any], overrides: Mapping[str, Any], where: str) -> None:
    """Set dotted keys in ``data`` (in order), resolving ``bundle_adjustment`` files.

    ``bundle_adjustment=true`` turns BA on with ``config/ba.yaml``, or keeps the settings it has
    when it is on already.
    """
    for key, value in overrides.items():
        *parents, name = key.split('.')
        node = data
        for depth, part in enumerate(parents):
            child = node.get(part)
            if child is None and part == 'bundle_adjustment' and depth == 0:
                raise ConfigError(f'{where}: {key}: bundle adjustment is off; turn it on first '
                                  '(bundle_adjustment=true)')
            if not isinstance(child, dict):
                raise ConfigError(f"{where}: {key}: {'.'.join(parents[:depth + 1])} is not a "
                                  'section of the engine settings')
            node = child
        if node is data and name == 'bundle_adjustment':
            if value is True and isinstance(node.get(name), dict):
                continue  # on already: its settings stand
            value = _resolved_ba({name: value}, f'{where}: {key}')[name]
        if isinstance(value, dict) and isinstance(node.get(name), dict):
            _merge(node[name], value)
        else:
            node[name] = copy.deepcopy(value)


def settings_yaml(config: EngineConfig, header: str = '') -> str:
    """Return ``config`` as an engine YAML, each setting under its description."""
    lines = [f'# {line}' if line else '#' for line in header.splitlines()]
    lines.append(f'{ENGINE_SECTION}:')
    _describe(config, 1, lines)
    return '\n'.join(lines) + '\n'


def _describe(config: Any, depth: int, lines: list[str]) -> None:
    """Append the fields of a dataclass, each with its description as a comment above it."""
    indent = '  ' * depth
    described = attribute_descriptions(type(config))
    for item in dataclasses.fields(config):
        value = getattr(config, item.name)
        text = described.get(item.name, '')
        for line in textwrap.wrap(text, _LINE_WIDTH - len(indent) - 2):
            lines.append(f'{indent}# {line}')
        if dataclasses.is_dataclass(value):
            lines.append(f'{indent}{item.name}:')
            _describe(value, depth + 1, lines)
        else:
            scalar = yaml.safe_dump(config_to_dict(value), default_flow_style=True,
                                    width=1000).strip()
            lines.append(f'{indent}{item.name}: {scalar.removesuffix(chr(10) + "...")}')


def attribute_descriptions(cls: type) -> dict[str, str]:
    """Return field name -> description: a field's ``parameter`` spec, else the docstring's.

    The docstring's ``Attributes:`` section is read in Google style (``name: text``, continued
    on deeper-indented lines).
    """
    found: dict[str, str] = {}
    doc = textwrap.dedent((cls.__doc__ or '').split('\n', 1)[-1])
    section = doc.partition('Attributes:')[2]
    name = None
    for line in section.splitlines():
        match = re.match(r'^    ([a-z_][a-z0-9_]*): (.*)$', line)
        if match:
            name = match.group(1)
            found[name] = match.group(2).strip()
        elif name and line.startswith('        '):
            found[name] += ' ' + line.strip()
        elif line.strip():
            name = None
    for item in dataclasses.fields(cls):
        spec = item.metadata.get('parameter')
        if spec is not None:
            found[item.name] = spec.full_description
    return found


def undescribed_settings(cls: type = EngineConfig, prefix: str = '') -> list[str]:
    """Return the dotted names of settings without a description (none, when all is well)."""
    missing = []
    described = attribute_descriptions(cls)
    hints = typing.get_type_hints(cls)
    for item in dataclasses.fields(cls):
        if not described.get(item.name):
            missing.append(f'{prefix}{item.name}')
        hint = hints[item.name]
        options = typing.get_args(hint) or (hint,)
        for option in options:
            if dataclasses.is_dataclass(option) and isinstance(option, type):
                missing += undescribed_settings(option, f'{prefix}{item.name}.')
    return missing


def packaged_yaml_text() -> str:
    """Return the text ``config/engine.yaml`` must hold: the defaults, described."""
    lines = []
    for name, keys in PROFILES.items():
        sets = ' '.join(f'{key}={value}' for key, value in keys.items()) or 'nothing'
        lines += textwrap.wrap(f'{name}: {PROFILE_HELP[name]}; sets {sets}', _LINE_WIDTH - 4,
                               initial_indent='  ', subsequent_indent='    ')
    profiles = '\n'.join(lines)
    header = ("The streaming engine's settings, generated from its dataclasses by\n"
              'python -m infinihand_ros.engine.settings --write (do not edit: a test compares '
              'them).\nThese are the defaults, the live profile. Named profiles change a few '
              'keys:\n' + profiles + '\nEntry points take --profile NAME and --set key=value '
              '(the node: engine.profile, engine.set);\na copy of this file, edited, is a '
              'settings file (--engine-config / engine.config).')
    return settings_yaml(EngineConfig(), header)


def save_engine_settings(config: EngineConfig, path: str | Path, profile: str = '',
                         overrides: Mapping[str, Any] | Iterable[str] = ()) -> Path:
    """Write the resolved settings an output was made with (loadable by ``load_engine_config``).

    The header names the profile and the overrides that produced them.
    """
    if not isinstance(overrides, Mapping):
        overrides = parse_overrides(overrides)
    described = ' '.join(f'{key}={value}' for key, value in overrides.items()) or 'none'
    header = (f'The engine settings this output was made with (profile {profile or "none"}; '
              f'overrides: {described}).')
    path = Path(path)
    atomic_write_bytes(path, settings_yaml(config, header).encode('utf-8'))
    return path


def add_settings_arguments(parser: argparse.ArgumentParser, default_profile: str | None,
                           default_text: str = '') -> None:
    """Add ``--profile``, ``--set`` and ``--engine-config`` to a command line.

    Args:
        parser: the command line.
        default_profile: the profile when ``--profile`` is not given (None: the caller's
            settings file decides; say which in ``default_text``).
        default_text: how the help names the default (default: ``default_profile``).

    """
    names = ', '.join(f'{name} ({text})' for name, text in PROFILE_HELP.items())
    parser.add_argument('--profile', choices=tuple(PROFILES), default=default_profile,
                        help=f'engine settings profile (default {default_text or default_profile})'
                             f': {names}')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE',
                        help='override one engine setting (dotted key, YAML value), after the '
                             'profile; repeatable, e.g. --set geometry_interval=1 --set '
                             'hands.source=mediapipe')
    parser.add_argument('--engine-config', type=Path,
                        help='engine settings file (config/engine.yaml layout, any subset of '
                             'its keys), applied between the profile and --set')


def main(argv: list[str] | None = None) -> int:
    """Write or check ``config/engine.yaml``, or print a profile's resolved settings."""
    parser = argparse.ArgumentParser(prog='python -m infinihand_ros.engine.settings',
                                     description=__doc__.split('\n', 1)[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument('--write', action='store_true', help='regenerate config/engine.yaml')
    group.add_argument('--check', action='store_true',
                       help='exit 1 when config/engine.yaml differs from the dataclasses')
    group.add_argument('--show', choices=tuple(PROFILES), help="print a profile's settings")
    args = parser.parse_args(argv)
    path = config_dir() / ENGINE_YAML
    if args.show:
        sys.stdout.write(settings_yaml(build_engine_config(args.show), f'profile {args.show}'))
        return 0
    expected = packaged_yaml_text()
    if args.write:
        atomic_write_bytes(path, expected.encode('utf-8'))
        print(f'wrote {path}')
        return 0
    current = path.read_text(encoding='utf-8') if path.is_file() else ''
    if current != expected:
        print(f'{path} differs from the engine dataclasses; run python -m '
              'infinihand_ros.engine.settings --write', file=sys.stderr)
        return 1
    print(f'{path} matches the engine dataclasses')
    return 0


if __name__ == '__main__':
    sys.exit(main())
