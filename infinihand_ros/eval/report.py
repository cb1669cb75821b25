"""The evaluation's report: markdown tables (the paper's metric names) and one JSON line."""

import json
import math
from typing import Final

from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.eval.baselines import BASELINES
from infinihand_ros.eval.detection_breakdown import DetectionBreakdown
from infinihand_ros.eval.detection_breakdown import MISS_CAUSES
from infinihand_ros.eval.runner import Evaluation
from infinihand_ros.eval.runner import Metrics

#: Table sections: title and the metrics it shows, with units.
TABLES: Final = (
    ('Detection', (('FAcc', ''), ('Recall', ''), ('F1', ''))),
    ('Camera space', (('MP-p', 'mm'), ('PA-p', 'mm'), ('EPE-p', 'px'), ('GO-p', 'deg'),
                      ('CT-p', 'm'))),
    ('World space', (('W-MPJPE', 'mm'), ('PA-MPJPE', 'mm'), ('WA-MPJPE', 'mm'))),
    ('Camera trajectory', (('ATE', 'm'), ('RPE-t', 'm'), ('RPE-r', 'deg'))),
)


def _cell(value: float | None) -> str:
    """Format a metric (4 significant digits; '-' when it does not apply)."""
    if value is None or not math.isfinite(value):
        return '-'
    return f'{value:.4g}'


def markdown_tables(evaluation: Evaluation) -> str:
    """Return one markdown table per section: rows ours and each baseline."""
    rows = [('ours', evaluation.ours)] + [(name, evaluation.baselines.get(name, {}))
                                          for name in BASELINES]
    parts = []
    for title, metrics in TABLES:
        header = [f'{name} ({unit})' if unit else name for name, unit in metrics]
        lines = [f'**{title}**', '', '| | ' + ' | '.join(header) + ' |',
                 '|---|' + '---|' * len(metrics)]
        for name, values in rows:
            cells = [_cell(values.get(metric)) for metric, _ in metrics]
            if name != 'ours' and all(cell == '-' for cell in cells):
                continue
            lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
        parts.append('\n'.join(lines))
    if evaluation.detection is not None:
        parts.append(breakdown_table(evaluation.detection))
    return '\n\n'.join(parts) + '\n'


def breakdown_table(breakdown: DetectionBreakdown) -> str:
    """Return the detection breakdown: recall per side and size, missed targets per cause."""
    sides = zip(SIDE_NAMES, breakdown.by_side)
    groups = [(f'{name} hands', count) for name, count in sides]
    groups += [(f'size {label}', count)
               for label, count in zip(breakdown.size_bins(), breakdown.by_size)]
    lines = ['**Detection breakdown** (size: sqrt(target box area) / image width W)', '',
             '| targets | count | Recall |', '|---|---|---|']
    lines += [f'| {name} | {count.targets} | {_cell(count.recall)} |' for name, count in groups]
    missed = sum(breakdown.misses.values())
    lines += ['', '| missed because | count | share |', '|---|---|---|']
    lines += [f'| {cause.replace("_", " ")} | {breakdown.misses[cause]} | '
              f'{_cell(breakdown.misses[cause] / missed if missed else float("nan"))} |'
              for cause in MISS_CAUSES]
    return '\n'.join(lines)


def sequence_table(evaluation: Evaluation) -> str:
    """Return a markdown table of the main per-sequence figures (ours)."""
    lines = ['| sequence | frames | fps | W-MPJPE (mm) | PA-MPJPE (mm) | WA-MPJPE (mm) | ATE (m) '
             '| frames/s |', '|---|---|---|---|---|---|---|---|']
    for item in evaluation.sequences:
        ours = item.ours
        lines.append(f'| {item.name} | {item.num_frames} | {item.fps:.3g} | '
                     f'{_cell(ours.get("W-MPJPE"))} | {_cell(ours.get("PA-MPJPE"))} | '
                     f'{_cell(ours.get("WA-MPJPE"))} | {_cell(ours.get("ATE"))} | '
                     f'{_cell(item.predictions.frames_per_s)} |')
    return '\n'.join(lines) + '\n'


def _finite(metrics: Metrics) -> dict[str, float | None]:
    """JSON-safe metrics (NaN becomes null)."""
    return {key: value if math.isfinite(value) else None for key, value in metrics.items()}


def json_line(evaluation: Evaluation, settings: dict[str, object]) -> str:
    """Return ``{"ours", "baselines", "sequences", "detection_breakdown", "settings"}`` as JSON."""
    return json.dumps({
        'ours': _finite(evaluation.ours),
        'baselines': {name: _finite(values) for name, values in evaluation.baselines.items()},
        'sequences': [{'name': item.name, 'frames': item.num_frames, 'fps': item.fps,
                       'frames/s': item.predictions.frames_per_s, 'ours': _finite(item.ours),
                       'baselines': {name: _finite(values)
                                     for name, values in item.baselines.items()}}
                      for item in evaluation.sequences],
        'detection_breakdown': (None if evaluation.detection is None
                                else evaluation.detection.as_dict()),
        'settings': settings}, sort_keys=False)
