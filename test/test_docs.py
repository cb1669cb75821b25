"""The documentation describes the product and stays short, current and linked.

The README, the bundled model's card and the architecture page have length limits; the README's
layout table matches the tree; every relative link in the README and ``docs/`` resolves; the
figures table in ``benchmarks/README.md`` is what ``benchmarks/figures.py`` builds from the
committed records.
"""

import importlib.util
import json
from pathlib import Path
import re

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
PACKAGE = ROOT / 'infinihand_ros'
#: Each page and its most lines.
LINE_LIMITS = {'README.md': 250, 'models/tiny_synthetic/README.md': 150,
               'docs/architecture.md': 150}
_LAYOUT_ROW = re.compile(r'^\| `([^`]+)` \|', re.MULTILINE)
_LINK = re.compile(r'\]\(([^)#\s]+)(?:#[^)]*)?\)')


def _section(text: str, heading: str) -> str:
    """Return the text of the ``## heading`` section of a markdown page."""
    assert f'\n## {heading}\n' in text, f'no "## {heading}" section'
    return text.split(f'\n## {heading}\n', 1)[1].split('\n## ', 1)[0]


def layout_paths(text: str) -> list[str]:
    """Return the paths of the README's layout table, e.g. ['infinihand_ros/core/', ...]."""
    return _LAYOUT_ROW.findall(_section(text, 'Layout'))


@pytest.mark.parametrize('page, limit', sorted(LINE_LIMITS.items()))
def test_page_is_short(page: str, limit: int) -> None:
    """Each page keeps within its line limit (reference material goes to docs/)."""
    lines = len((ROOT / page).read_text(encoding='utf-8').splitlines())
    assert lines <= limit, f'{page} has {lines} lines, at most {limit}'


def test_layout_table_matches_the_tree() -> None:
    """Every layout path exists, and every first-level subpackage has a row."""
    paths = layout_paths(README.read_text(encoding='utf-8'))
    missing = [path for path in paths if not (ROOT / path).exists()]
    assert not missing, f'layout rows for paths that do not exist: {missing}'
    subpackages = sorted(f'infinihand_ros/{child.name}/' for child in PACKAGE.iterdir()
                         if (child / '__init__.py').is_file())
    absent = [package for package in subpackages if package not in paths]
    assert not absent, f'subpackages without a layout row: {absent}'


def test_layout_extraction_reads_the_first_column() -> None:
    """Rows of the Layout section are read; other tables are not."""
    text = ('# x\n\n## Other\n\n| `a/` | no |\n\n## Layout\n\n| path | what |\n|---|---|\n'
            '| `infinihand_ros/core/` | types |\n| `docs/` | reference |\n\n## Next\n\n'
            '| `b/` | no |\n')
    assert layout_paths(text) == ['infinihand_ros/core/', 'docs/']


@pytest.mark.parametrize('page', [
    'README.md', 'benchmarks/README.md', 'models/tiny_synthetic/README.md',
    *sorted(str(path.relative_to(ROOT)) for path in (ROOT / 'docs').glob('*.md'))])
def test_relative_links_resolve(page: str) -> None:
    """Every relative link of the READMEs and the docs/ pages points at an existing file."""
    path = ROOT / page
    links = [link for link in _LINK.findall(path.read_text(encoding='utf-8'))
             if '://' not in link]
    broken = [link for link in links if not (path.parent / link).exists()]
    assert not broken, f'{page} links to missing files: {broken}'


def _benchmark_module(name: str):
    """Import benchmarks/<name>.py (a script, not a package module)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / 'benchmarks' / f'{name}.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_figures_table_is_generated() -> None:
    """benchmarks/README.md's table equals what benchmarks/figures.py builds from the records."""
    figures = _benchmark_module('figures')
    records = figures.load_records()
    assert records, 'no benchmark records in benchmarks/results/'
    current = figures.README.read_text(encoding='utf-8')
    assert figures.rebuilt(current, records) == current, (
        'benchmarks/README.md is out of date: run python benchmarks/figures.py')


def test_figures_table_has_one_row_per_figure() -> None:
    """A record with two figures gives two rows carrying its command, machine, commit, date."""
    figures = _benchmark_module('figures')
    record = {'benchmark': 'b', 'command': 'python benchmarks/b.py --x', 'machine': 'm, 2 CPUs',
              'commit': 'abc1234', 'date': '2026-01-02', 'load_average': 3.5,
              'figures': [{'name': 'speed', 'value': 12.3456, 'unit': 'frames/s'},
                          {'name': 'error', 'value': 0.5, 'unit': ''}]}
    rows = figures.table([record]).splitlines()
    assert rows[2] == ('| speed | 12.3 frames/s | `python benchmarks/b.py --x` | '
                       'm, 2 CPUs, load 3.5 | `abc1234` | 2026-01-02 |')
    assert rows[3].startswith('| error | 0.5 | ')
    assert len(rows) == 4
    with pytest.raises(ValueError, match='marker lines'):
        figures.rebuilt('no markers', [record])


def test_record_names_how_the_figures_were_made(tmp_path: Path) -> None:
    """A record carries the figures, command, machine, commit, date, load; NaN is refused."""
    records = _benchmark_module('records')
    path = tmp_path / 'results' / 'x.json'
    records.write_record(path, 'x', [records.Figure('speed', 2.5, 'frames/s')])
    record = json.loads(path.read_text(encoding='utf-8'))
    assert tuple(record) == records.RECORD_KEYS
    assert record['figures'] == [{'name': 'speed', 'value': 2.5, 'unit': 'frames/s'}]
    assert 'CPUs' in record['machine'] and record['command'].startswith('python ')
    with pytest.raises(ValueError, match="figure 'bad' of x: value nan"):
        records.write_record(path, 'x', [records.Figure('bad', float('nan'), '')])
