"""ament_copyright where the linter is installed (no PyPI wheel exists, so it usually skips)."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
@pytest.mark.copyright
def test_copyright() -> None:
    """Every source file carries a copyright notice accepted by ament_copyright."""
    main = pytest.importorskip('ament_copyright.main').main
    rc = main(argv=[str(ROOT / 'infinihand_ros'), str(ROOT / 'test')])
    assert rc == 0, 'Found errors'
