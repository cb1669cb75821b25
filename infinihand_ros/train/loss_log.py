"""The loss log of a run (JSON lines or CSV) and its PNG curves (drawn with OpenCV).

One record per logged step: ``step``, ``loss`` (L_joint), every term (``mask.bce``, ...), the
learning rate of each parameter group (``lr.<group>``), the gradient norm before clipping and
the throughput (``clips_per_s``). Resuming truncates the log to the resumed step first, so the
log of a resumed run reads like the log of an uninterrupted one. Curves: ``loss_curves.png``,
one panel per loss group total and L_joint, log-scale y.
"""

import csv
import io
import json
import math
from pathlib import Path
from typing import Final

import cv2
from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.errors import InputError
import numpy as np

JSONL_FILE: Final = 'loss_log.jsonl'
CSV_FILE: Final = 'loss_log.csv'
CURVES_FILE: Final = 'loss_curves.png'
_PANEL_SIZE: Final = (360, 240)  # width, height of one curve panel, pixels
_MARGIN: Final = 36
_COLUMNS: Final = 3


class LossLog:
    """Append-only loss records in ``output`` (``jsonl`` or ``csv``), kept in memory too."""

    def __init__(self, output: str | Path, log_format: str, resume_step: int | None = None
                 ) -> None:
        """Open the log; with ``resume_step``, keep only the records up to that step.

        Raises:
            InputError: for an unknown format.

        """
        if log_format not in ('jsonl', 'csv'):
            raise InputError(f'loss log format {log_format!r}: use jsonl or csv')
        self.output = Path(output)
        self.log_format = log_format
        self.path = self.output / (JSONL_FILE if log_format == 'jsonl' else CSV_FILE)
        self.records: list[dict[str, float]] = []
        if resume_step is not None and self.path.is_file():
            self.records = [record for record in self._read() if record['step'] <= resume_step]
        self._rewrite()

    def _read(self) -> list[dict[str, float]]:
        """Return the records of the existing log file."""
        text = self.path.read_text(encoding='utf-8')
        if self.log_format == 'jsonl':
            return [json.loads(line) for line in text.splitlines() if line.strip()]
        return [{key: float(value) for key, value in row.items() if value != ''}
                for row in csv.DictReader(io.StringIO(text))]

    def _rewrite(self) -> None:
        """Write every record again (atomically; CSV needs it when new columns appear)."""
        if self.log_format == 'jsonl':
            text = ''.join(json.dumps(record) + '\n' for record in self.records)
        else:
            columns = list(dict.fromkeys(key for record in self.records for key in record))
            stream = io.StringIO()
            writer = csv.DictWriter(stream, fieldnames=columns)
            writer.writeheader()
            writer.writerows(self.records)
            text = stream.getvalue() if self.records else ''
        atomic_write_bytes(self.path, text.encode('utf-8'))

    def append(self, record: dict[str, float]) -> None:
        """Add one record (``step`` first) and write it out."""
        self.records.append(record)
        if self.log_format == 'jsonl':
            with self.path.open('a', encoding='utf-8') as stream:
                stream.write(json.dumps(record) + '\n')
        else:
            self._rewrite()

    def write_curves(self) -> Path:
        """Draw ``loss_curves.png`` from the records; return its path."""
        names = ['loss'] + sorted({key for record in self.records for key in record
                                   if key.endswith('.total')})
        image = draw_curves(self.records, names)
        ok, png = cv2.imencode('.png', image)
        if not ok:
            raise InputError('loss curves: OpenCV could not encode the PNG')
        path = self.output / CURVES_FILE
        atomic_write_bytes(path, png.tobytes())
        return path


def draw_curves(records: list[dict[str, float]], names: list[str]) -> np.ndarray:
    """Return a BGR image with one panel per name: value against step, log10 y axis."""
    rows = max(1, math.ceil(len(names) / _COLUMNS))
    width, height = _PANEL_SIZE
    image = np.full((rows * height, _COLUMNS * width, 3), 255, np.uint8)
    for index, name in enumerate(names):
        top, left = (index // _COLUMNS) * height, (index % _COLUMNS) * width
        points = [(record['step'], record[name]) for record in records
                  if name in record and math.isfinite(record[name]) and record[name] > 0]
        panel = np.full((height, width, 3), 255, np.uint8)  # OpenCV draws on contiguous arrays
        _draw_panel(panel, name, points)
        image[top:top + height, left:left + width] = panel
    return image


def _draw_panel(panel: np.ndarray, name: str, points: list[tuple[float, float]]) -> None:
    """Draw one curve with its axes' ranges into ``panel`` (in place)."""
    height, width = panel.shape[:2]
    x0, y0, x1, y1 = _MARGIN, _MARGIN // 2, width - _MARGIN // 2, height - _MARGIN
    cv2.rectangle(panel, (x0, y0), (x1, y1), (180, 180, 180), 1)
    cv2.putText(panel, name, (x0 + 4, y0 + 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1,
                cv2.LINE_AA)
    if not points:
        return
    steps = np.array([point[0] for point in points], np.float64)
    values = np.log10(np.array([point[1] for point in points], np.float64))
    low, high = values.min(), values.max()
    high = high if high > low else low + 1.0
    first, last = steps.min(), steps.max()
    last = last if last > first else first + 1.0
    xs = x0 + (steps - first) / (last - first) * (x1 - x0)
    ys = y1 - (values - low) / (high - low) * (y1 - y0)
    curve = np.stack((xs, ys), axis=1).round().astype(np.int32)
    cv2.polylines(panel, [curve], False, (200, 90, 30), 1, cv2.LINE_AA)
    labels = ((f'{10 ** high:.3g}', (2, y0 + 10)), (f'{10 ** low:.3g}', (2, y1)),
              (f'{int(first)}', (x0, height - 8)), (f'{int(last)}', (x1 - 40, height - 8)))
    for text, origin in labels:
        cv2.putText(panel, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.35, (60, 60, 60), 1,
                    cv2.LINE_AA)
