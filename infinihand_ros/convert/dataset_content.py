"""A dataset's content, for comparing two conversions (a resumed run against an uninterrupted one).

Data and episode tables are compared by value, JSON metadata by value without what depends on
the run rather than the inputs (wall times, frames per second), the card and the videos byte
for byte.
"""

import json
from pathlib import Path
from typing import Any, Final

from infinihand_ros.convert import lerobot_layout as layout
from infinihand_ros.convert.dataset_card import CARD_FILE
import pyarrow.parquet as pq

#: Report fields that measure the run (time), not the data.
RUN_FIELDS: Final = ('seconds', 'frames_per_s')
#: The last run's report (not the dataset's) and the bags of estimates (MCAP, written with
#: their own stamps) are not compared.
LAST_REPORT: Final = 'conversion_report.json'
ESTIMATES_DIR: Final = 'estimates/'


def _without_run_fields(conversion: dict[str, Any]) -> dict[str, Any]:
    for record in conversion['episodes']:
        for name in RUN_FIELDS:
            record['report'].pop(name, None)
    return conversion


def _left_out(relative: str) -> bool:
    return (relative == LAST_REPORT or relative.startswith(ESTIMATES_DIR)
            or any(part.startswith('.') for part in relative.split('/')))


def dataset_content(root: Path) -> dict[str, Any]:
    """Return relative path -> content of every file of the dataset at ``root``.

    Parquet files become their rows, JSON files their values (the conversion record without
    ``RUN_FIELDS``), the card and the videos their bytes. Staging leftovers (names starting
    with '.'), ``LAST_REPORT`` and ``ESTIMATES_DIR`` are left out.
    """
    root = Path(root)
    content: dict[str, Any] = {}
    for path in sorted(root.rglob('*')):
        relative = path.relative_to(root).as_posix()
        if not path.is_file() or _left_out(relative):
            continue
        if path.suffix == '.parquet':
            content[relative] = pq.read_table(path).to_pylist()
        elif relative == layout.CONVERSION_PATH:
            content[relative] = _without_run_fields(json.loads(path.read_text(encoding='utf-8')))
        elif path.suffix == '.json':
            content[relative] = json.loads(path.read_text(encoding='utf-8'))
        elif relative == CARD_FILE or path.suffix == '.mp4':
            content[relative] = path.read_bytes()
    return content
