"""Typed configuration: YAML sections into frozen dataclasses, rejecting unknown keys and types.

Every component has one frozen dataclass config; values live in ``config/*.yaml``. This module is
the single loader: ``load_config(path, 'section', MyConfig)``. Missing fields keep their defaults
unless ``require_complete=True`` (for files that must describe a configuration in full, such as
the one saved beside a checkpoint).
"""

import dataclasses
import math
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
        options = [option for option in typing.get_args(hint) if option is not type(None)]
        if value is None and len(options) < len(typing.get_args(hint)):
            return None
        if len(options) == 1:  # ``X | None``: report why the value is not an X (naming its key)
            return _check_value(value, options[0], where)
        for option in options:
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
    """Raise ConfigError naming the first of ``values`` that is not positive (NaN is not)."""
    for name, value in values.items():
        if not value > 0:
            raise ConfigError(f'{owner}.{name}: must be positive, got {value!r}')


def require_at_least(owner: str, minimum: float, **values: float) -> None:
    """Raise ConfigError naming the first of ``values`` below ``minimum`` (NaN is below)."""
    for name, value in values.items():
        if not value >= minimum:
            raise ConfigError(f'{owner}.{name}: must be >= {minimum}, got {value!r}')


def require_finite(owner: str, **values: float) -> None:
    """Raise ConfigError naming the first of ``values`` that is NaN or infinite."""
    for name, value in values.items():
        if not math.isfinite(value):
            raise ConfigError(f'{owner}.{name}: must be a finite number, got {value!r}')


def _missing_keys(cls: type, data: dict, prefix: str = '') -> list[str]:
    """Return the dotted names of ``cls`` fields absent from ``data``, nested sections included.

    A nested section that is present but not a mapping is left to the type check.
    """
    hints = typing.get_type_hints(cls)
    missing = []
    for field in dataclasses.fields(cls):
        name = f'{prefix}{field.name}'
        if field.name not in data:
            missing.append(name)
            continue
        value, hint = data[field.name], hints[field.name]
        options = typing.get_args(hint) if typing.get_origin(hint) in (
            typing.Union, types.UnionType) else (hint,)
        nested = [option for option in options
                  if dataclasses.is_dataclass(option) and isinstance(option, type)]
        if len(nested) == 1 and isinstance(value, dict):
            missing += _missing_keys(nested[0], value, f'{name}.')
    return missing


def config_from_dict(cls: type[ConfigT], data: Any, where: str, *,
                     require_complete: bool = False) -> ConfigT:
    """Build the dataclass ``cls`` from a mapping, checking keys and types.

    Args:
        cls: a (frozen) dataclass type; nested dataclass fields are built recursively.
        data: mapping from field name to value (missing fields keep their defaults unless
            ``require_complete``).
        where: name of the source used in error messages (file and section).
        require_complete: refuse a mapping that leaves out any field, at any depth, instead of
            filling in defaults.

    Raises:
        ConfigError: for a non-mapping, an unknown key, a wrong type or a rejected value, and
            with ``require_complete`` for missing keys (listed with their dotted paths).

    """
    if not isinstance(data, dict):
        raise ConfigError(f'{where}: expected a mapping of {cls.__name__} fields, got {data!r}')
    hints = typing.get_type_hints(cls)
    names = {field.name for field in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(f'{where}: unknown key(s) {unknown}; valid keys are {sorted(names)}')
    if require_complete:
        missing = _missing_keys(cls, data)
        if missing:
            raise ConfigError(f'{where}: missing key(s) {missing}; this file must give every '
                              f'{cls.__name__} field (defaults are not filled in)')
    values = {key: _check_value(value, hints[key], f'{where}.{key}')
              for key, value in data.items()}
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{where}: {exc}') from exc


def read_yaml(path: str | Path) -> Any:
    """Return the parsed YAML document of the UTF-8 file ``path`` (None for an empty file).

    Raises:
        ConfigError: naming ``path`` when it cannot be read, is not UTF-8 or is not YAML.

    """
    path = Path(path)
    try:
        return yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as exc:
        raise ConfigError(f'{path}: cannot read the configuration file ({exc})') from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f'{path}: not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset '
                          f'{exc.start}); save the file as UTF-8') from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f'{path}: not valid YAML ({exc})') from exc


def load_config(path: str | Path, section: str, cls: type[ConfigT], *,
                require_complete: bool = False) -> ConfigT:
    """Load ``section`` of the YAML file ``path`` into the dataclass ``cls``.

    Args:
        path: the YAML file (UTF-8).
        section: the top-level key holding the ``cls`` fields.
        cls: the (frozen) dataclass to build.
        require_complete: every field of ``cls`` (nested sections included) must be in the file;
            False fills missing fields with their defaults.

    Raises:
        ConfigError: when the file is missing, not UTF-8 or not YAML, the section is absent, a
            value is unknown, mistyped or rejected by the dataclass, or (with
            ``require_complete``) a field is missing.

    """
    path = Path(path)
    document = read_yaml(path)
    if not isinstance(document, dict) or section not in document:
        raise ConfigError(f'{path}: no top-level section {section!r}')
    return config_from_dict(cls, document[section], f'{path}:{section}',
                            require_complete=require_complete)


def config_to_dict(config: Any) -> Any:
    """Return a dataclass config as plain YAML data (tuples become lists), nested included."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return {item.name: config_to_dict(getattr(config, item.name))
                for item in dataclasses.fields(config)}
    if isinstance(config, (list, tuple)):
        return [config_to_dict(value) for value in config]
    return config


def dump_config(config: Any, section: str) -> str:
    """Return the YAML text ``{section: config}`` that ``load_config`` reads back to ``config``.

    Every field is written (resolved defaults included), so the text also loads with
    ``require_complete=True``.
    """
    return yaml.safe_dump({section: config_to_dict(config)}, sort_keys=False)


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
