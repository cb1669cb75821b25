"""ament_pep257 over the package and the tests."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHECKED_PATHS = [ROOT / name for name in ('infinihand_ros', 'test', 'benchmarks')
                 if (ROOT / name).exists()]
#: ament's convention plus Google-style docstrings (STYLE.md): the summary sits on the first line
#: (D213 off; ament already ignores D212) and sections are written 'Args:' without dashed
#: underlines (D406, D407 off).
GOOGLE_STYLE_IGNORES = ['D213', 'D406', 'D407']


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257() -> None:
    """The docstrings follow pep257 under ament's configuration."""
    main = pytest.importorskip('ament_pep257.main').main
    argv = ['--add-ignore', *GOOGLE_STYLE_IGNORES, '--', *[str(path) for path in CHECKED_PATHS]]
    rc = main(argv=argv)
    assert rc == 0, 'Found code style errors / warnings'
