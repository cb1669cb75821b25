"""ament_flake8 over the package, tests and scripts (99 columns, single quotes, google order)."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHECKED_PATHS = [ROOT / name for name in ('infinihand_ros', 'test', 'benchmarks', 'setup.py')
                 if (ROOT / name).exists()]


@pytest.mark.linter
@pytest.mark.flake8
def test_flake8() -> None:
    """The code has no flake8 errors under ament's configuration."""
    main_with_errors = pytest.importorskip('ament_flake8.main').main_with_errors
    rc, errors = main_with_errors(argv=[str(path) for path in CHECKED_PATHS])
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
