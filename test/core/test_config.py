"""The typed YAML loader: values converted to the dataclass's types, anything else refused."""

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import read_yaml
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_finite
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
import pytest


@dataclass(frozen=True)
class _Inner:
    size: tuple[int, int] = (1, 2)


@dataclass(frozen=True)
class _Settings:
    rate: float = 1.0
    name: str = 'a'
    limit: int | None = None
    inner: _Inner = _Inner()

    def __post_init__(self) -> None:
        if self.rate <= 0:
            raise ValueError(f'rate must be positive, got {self.rate}')


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / 'settings.yaml'
    path.write_text(text)
    return path


def test_values_are_converted_and_defaults_kept(tmp_path: Path) -> None:
    path = _write(tmp_path, 'part: {rate: 2, limit: 5, inner: {size: [3, 4]}}\n')
    assert load_config(path, 'part', _Settings) == _Settings(rate=2.0, limit=5,
                                                             inner=_Inner((3, 4)))


@pytest.mark.parametrize(('text', 'message'), [
    ('part: {rat: 2}', r"part: unknown key\(s\) \['rat'\]"),
    ('part: {rate: yes}', 'part.rate: expected a number, got True'),
    ('part: {limit: 1.5}', 'part.limit: expected int, got 1.5'),
    ('part: {inner: {size: [1]}}', r'part.inner.size: expected 2 values, got 1'),
    ('part: {rate: -1}', 'rate must be positive, got -1.0'),
    ('other: {}', "no top-level section 'part'"),
    ('part: [1', 'not valid YAML'),
])
def test_bad_values_name_the_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=message) as error:
        load_config(path, 'part', _Settings)
    assert str(path) in str(error.value)


def test_non_utf8_file_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / 'latin1.yaml'
    path.write_bytes('part: {name: caf\u00e9}\n'.encode('latin-1'))
    with pytest.raises(ConfigError, match=r'not UTF-8 text \(byte 0xe9 at offset 16\)') as error:
        load_config(path, 'part', _Settings)
    assert str(path) in str(error.value)


def test_complete_file_is_required_on_request(tmp_path: Path) -> None:
    full = 'part: {rate: 2, name: b, limit: null, inner: {size: [3, 4]}}\n'
    assert load_config(_write(tmp_path, full), 'part', _Settings,
                       require_complete=True) == _Settings(2.0, 'b', None, _Inner((3, 4)))
    path = _write(tmp_path, 'part: {rate: 2, inner: {}}\n')
    assert load_config(path, 'part', _Settings) == _Settings(rate=2.0)
    with pytest.raises(ConfigError, match=r":part: missing key\(s\) \['name', 'limit', "
                                          r"'inner.size'\]; this file must give every "
                                          '_Settings field') as error:
        load_config(path, 'part', _Settings, require_complete=True)
    assert str(path) in str(error.value)
    with pytest.raises(ConfigError, match=r"missing key\(s\) \['rate', 'name', 'limit', "
                                          r"'inner'\]"):
        load_config(_write(tmp_path, 'part: {}\n'), 'part', _Settings, require_complete=True)


@pytest.mark.parametrize(('check', 'value', 'message'), [
    (require_positive, float('nan'), 'part.value: must be positive, got nan'),
    (require_positive, 0, 'part.value: must be positive, got 0'),
    (require_finite, float('inf'), 'part.value: must be a finite number, got inf'),
    (require_finite, float('nan'), 'part.value: must be a finite number, got nan'),
])
def test_value_checks_name_the_key(check: Callable[..., None], value: float,
                                   message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        check('part', value=value)
    check('part', value=1.5)


def test_minimum_check_names_the_key() -> None:
    require_at_least('part', 3, window=3)
    for bad in (2, float('nan')):
        with pytest.raises(ConfigError, match=f'part.window: must be >= 3, got {bad}'):
            require_at_least('part', 3, window=bad)


def test_unknown_key_is_reported_before_missing_ones(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"unknown key\(s\) \['rat'\]"):
        load_config(_write(tmp_path, 'part: {rat: 2}\n'), 'part', _Settings,
                    require_complete=True)


def test_read_yaml_returns_the_document_or_a_config_error(tmp_path: Path) -> None:
    assert read_yaml(_write(tmp_path, 'a: [1, 2]\n')) == {'a': [1, 2]}
    with pytest.raises(ConfigError, match='cannot read the configuration file'):
        read_yaml(tmp_path / 'missing.yaml')
    (tmp_path / 'bad.yaml').write_bytes(b'a: \xff\n')
    with pytest.raises(ConfigError, match=r'bad.yaml: not UTF-8 text \(byte 0xff at offset 3\)'):
        read_yaml(tmp_path / 'bad.yaml')


@dataclass(frozen=True)
class _Outer:
    optional: _Settings | None = None
    either: int | str = 0


def test_optional_section_errors_name_the_nested_key(tmp_path: Path) -> None:
    path = _write(tmp_path, 'part: {optional: {inner: {size: [1, x]}}}\n')
    with pytest.raises(ConfigError, match=r'part.optional.inner.size\[1\]: expected int'):
        load_config(path, 'part', _Outer)
    assert load_config(_write(tmp_path, 'part: {optional: null, either: b}\n'), 'part',
                       _Outer) == _Outer(None, 'b')
    with pytest.raises(ConfigError, match=r'part.either: \[1\] matches none of int \| str'):
        load_config(_write(tmp_path, 'part: {either: [1]}\n'), 'part', _Outer)
