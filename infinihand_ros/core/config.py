"""Typed configuration: YAML sections into frozen dataclasses, rejecting unknown keys and types.

Every component has one frozen dataclass config; values live in ``config/*.yaml``. This module is
the single loader: ``load_config(path, 'section', MyConfig)``.
"""

import dataclasses
from pathlib import Path
import types
import typing
from typing import Any, TypeVar

from infinihand_ros.core.errors import ConfigError
import yaml

ConfigT = TypeVar('ConfigT')


def _check_value(value: Any, hint: Any, where: str) -> Any:
    """Return ``value`` converted to ``hint`` or raise ConfigError naming ``where``."""
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return config_from_dict(hint, value, where)
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(hint):
            try:
                return _check_value(value, option, where)
            except ConfigError:
                continue
        raise ConfigError(f'{where}: {value!r} matches none of {hint}')
    if hint is type(None):
        if value is not None:
            raise ConfigError(f'{where}: expected null, got {value!r}')
        return None
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f'{where}: expected a list, got {value!r}')
        args = typing.get_args(hint)
        item_hints = [args[0]] * len(value) if len(args) == 2 and args[1] is Ellipsis else args
        if len(item_hints) != len(value):
            raise ConfigError(f'{where}: expected {len(item_hints)} values, got {len(value)}')
        return tuple(_check_value(v, h, f'{where}[{i}]')
                     for i, (v, h) in enumerate(zip(value, item_hints)))
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f'{where}: expected a number, got {value!r}')
        return float(value)
    if hint in (int, str, bool):
        if not isinstance(value, hint) or (hint is int and isinstance(value, bool)):
            raise ConfigError(f'{where}: expected {hint.__name__}, got {value!r}')
        return value
    raise ConfigError(f'{where}: unsupported field type {hint}')


def require_positive(owner: str, **values: float) -> None:
    """Raise ConfigError naming the first of ``values`` that is not positive."""
    for name, value in values.items():
        if value <= 0:
            raise ConfigError(f'{owner}.{name}: must be positive, got {value!r}')


def config_from_dict(cls: type[ConfigT], data: Any, where: str) -> ConfigT:
    """Build the dataclass ``cls`` from a mapping, checking keys and types.

    Args:
        cls: a (frozen) dataclass type; nested dataclass fields are built recursively.
        data: mapping from field name to value (missing fields keep their defaults).
        where: name of the source used in error messages (file and section).

    Raises:
        ConfigError: for a non-mapping, an unknown key, a wrong type or a rejected value.

    """
    if not isinstance(data, dict):
        raise ConfigError(f'{where}: expected a mapping of {cls.__name__} fields, got {data!r}')
    hints = typing.get_type_hints(cls)
    names = {field.name for field in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(f'{where}: unknown key(s) {unknown}; valid keys are {sorted(names)}')
    values = {key: _check_value(value, hints[key], f'{where}.{key}')
              for key, value in data.items()}
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{where}: {exc}') from exc


def load_config(path: str | Path, section: str, cls: type[ConfigT]) -> ConfigT:
    """Load ``section`` of the YAML file ``path`` into the dataclass ``cls``.

    Raises:
        ConfigError: when the file is missing or not YAML, the section is absent, or a value is
            unknown, mistyped or rejected by the dataclass.

    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as exc:
        raise ConfigError(f'{path}: cannot read the configuration file ({exc})') from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f'{path}: not valid YAML ({exc})') from exc
    if not isinstance(document, dict) or section not in document:
        raise ConfigError(f'{path}: no top-level section {section!r}')
    return config_from_dict(cls, document[section], f'{path}:{section}')


def package_share_dir(name: str) -> Path:
    """Return the package's ``name`` directory (source tree first, else the installed share dir).

    Raises:
        ConfigError: when neither exists.

    """
    source_dir = Path(__file__).resolve().parents[2] / name
    if source_dir.is_dir():
        return source_dir
    try:
        from ament_index_python.packages import get_package_share_directory
    except ImportError as exc:
        raise ConfigError(f'cannot find {name}/: not in a source tree and ament_index_python '
                          'is unavailable; source scripts/env.sh') from exc
    return Path(get_package_share_directory('infinihand_ros')) / name


def config_dir() -> Path:
    """Return the package's ``config/`` directory."""
    return package_share_dir('config')
