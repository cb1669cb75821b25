"""Composition of training files: a ``base`` file plus overrides, and dotted ``--set`` values.

A training file may name a base, ``base: train_tiny.yaml`` (a path relative to the file's own
folder), and give only what differs: its sections are deep-merged over the base's (mappings
merge key by key; any other value, a list included, replaces the base's). A base may have a
base of its own. Dotted overrides (``train --set train.steps=500 losses.camera.weight=5.0``)
then replace single values, each read as YAML (``train.data.sequences=[a, b]``); their keys are
checked against the config dataclasses, so a typo names the key and the valid ones. The result
is the resolved document, with no ``base`` left: the loader builds the config from it, and the
trainer saves that config beside every checkpoint.
"""

from collections.abc import Mapping
import copy
import dataclasses
from pathlib import Path
import typing
from typing import Any
from typing import Final

from infinihand_ros.core.config import read_yaml
from infinihand_ros.core.errors import ConfigError
import yaml

#: Top-level key of a training file naming the file it overrides.
BASE_KEY: Final = 'base'
#: Separator of a dotted override's key and value.
_ASSIGN: Final = '='


def read_composed(path: str | Path) -> dict[str, Any]:
    """Return the document of ``path`` merged over its chain of base files (``base`` removed).

    Raises:
        ConfigError: for an unreadable file, a document that is not a mapping, a ``base`` that
            is not a file name, or a cycle of bases, naming the file.

    """
    return _compose(Path(path), ())


def _compose(path: Path, seen: tuple[Path, ...]) -> dict[str, Any]:
    """Return ``path``'s document over its base's; ``seen`` are the files that named it."""
    resolved = path.resolve()
    if resolved in seen:
        chain = ' -> '.join(str(item) for item in (*seen, resolved))
        raise ConfigError(f'{path}: the {BASE_KEY} files form a cycle ({chain})')
    document = read_yaml(path)
    if not isinstance(document, dict):
        raise ConfigError(f'{path}: expected a mapping of top-level sections, got {document!r}')
    document = dict(document)
    if BASE_KEY not in document:
        return document
    base = document.pop(BASE_KEY)
    if not isinstance(base, str) or not base:
        raise ConfigError(f'{path}:{BASE_KEY}: expected a file name relative to {path.parent}, '
                          f'got {base!r}')
    return merge_documents(_compose(path.parent / base, (*seen, resolved)), document)


def merge_documents(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``base`` with ``override`` deep-merged over it (neither is modified)."""
    merged = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = merge_documents(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def parse_override(text: str) -> tuple[str, Any]:
    """Return (key, value) of a ``key.sub=value`` override, the value read as YAML.

    Raises:
        ConfigError: naming the text when it has no ``=`` or no key, or its value is not YAML.

    """
    key, assign, value = text.partition(_ASSIGN)
    key = key.strip()
    if not assign or not key:
        raise ConfigError(f'--set {text!r}: expected KEY=VALUE, e.g. train.steps=500')
    try:
        return key, yaml.safe_load(value)
    except yaml.YAMLError as exc:
        raise ConfigError(f'--set {key}: the value {value!r} is not YAML ({exc})') from exc


def apply_overrides(document: Mapping[str, Any], overrides: Mapping[str, Any],
                    schema: Mapping[str, type]) -> dict[str, Any]:
    """Return ``document`` with each dotted ``key: value`` of ``overrides`` set in it.

    Args:
        document: the composed document (top-level sections).
        overrides: dotted keys (``train.clip.frame_stride``) and their values.
        schema: the dataclass of each top-level section the keys may start with.

    Raises:
        ConfigError: naming the key when a part of it is no field of its section, or a part
            before the last is a value rather than a section.

    """
    result = copy.deepcopy(dict(document))
    for key, value in overrides.items():
        parts = key.split('.')
        _check_key(key, parts, schema)
        node = result
        for depth, part in enumerate(parts[:-1]):
            if node.get(part) is None:
                node[part] = {}
            node = node[part]
            if not isinstance(node, dict):
                raise ConfigError(f'--set {key}: {".".join(parts[:depth + 1])} is {node!r} '
                                  f'in the file, not a section')
        node[parts[-1]] = copy.deepcopy(value)
    return result


def _check_key(key: str, parts: list[str], schema: Mapping[str, type]) -> None:
    """Raise ConfigError unless ``parts`` walk the schema's dataclasses to a field."""
    cls = schema.get(parts[0])
    if cls is None:
        raise ConfigError(f'--set {key}: a key starts with one of {sorted(schema)} '
                          f'(e.g. train.steps)')
    if not all(parts) or len(parts) < 2:
        raise ConfigError(f'--set {key}: expected a dotted key such as train.steps')
    for depth, part in enumerate(parts[1:], start=1):
        names = [field.name for field in dataclasses.fields(cls)]
        where = '.'.join(parts[:depth])
        if part not in names:
            raise ConfigError(f'--set {key}: {where} has no key {part!r}; valid keys are '
                              f'{sorted(names)}')
        hint = typing.get_type_hints(cls)[part]
        if depth < len(parts) - 1:
            if not (isinstance(hint, type) and dataclasses.is_dataclass(hint)):
                raise ConfigError(f'--set {key}: {where}.{part} is a value, not a section; '
                                  f'set it whole ({where}.{part}=...)')
            cls = hint
