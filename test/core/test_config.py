"""The typed YAML loader: values converted to the dataclass's types, anything else refused."""

from dataclasses import dataclass
from pathlib import Path

from infinihand_ros.core.config import load_config
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
    ('part: {limit: 1.5}', 'part.limit: 1.5 matches none of'),
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
