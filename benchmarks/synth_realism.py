"""Realism of the synthetic hands: how many MediaPipe Hands finds and how well it agrees.

    python benchmarks/synth_realism.py [--seeds 25000 ... 25007] [--frames 60] [--size 336x252]
        [--json] [--save-preview PATH]

Generates synthetic sequences (both hands; by default seeds 25000-25007, a range no training or
evaluation set uses) and runs MediaPipe Hands on them as it is (video mode, its palm detector
whenever it tracks fewer than two hands: ``hands.search_interval: 1``; ``reset`` between sequences,
detections scoring at least ``hands.min_confidence``). A visible truth hand (at least
``synth.min_visible_px`` pixels in view) is found when a detection of the same side overlaps its
box (IoU of the detection's landmark box with the truth's mask box at least 0.3); found regardless
of side is counted apart (side swaps). Whole hands are the visible ones whose 21 joints all lie in
the image, cut hands the others; overlapping hands are whole hands whose box overlaps another
visible hand's. PCK@0.2 over the found hands: the share of their truth joints inside the image (and
in front of the camera) whose detection lies within 0.2 of the truth box's longer side. A detection
overlapping no visible truth hand (either side) is a false positive. Isolated hands are the whole
ones that overlap no other; the ceiling is the found share if every isolated hand were found and
the others as they are: what realism of the hands alone can reach with the sequences' framing.
Prints per seed and overall, beside the targets of issue 39 (found >= 90 %, PCK@0.2 >= 80 %),
with MediaPipe's median ms/frame.
``--save-preview`` writes a PNG grid of each sequence's middle frame: truth boxes green, detections
red. Figures only; nothing is asserted.
"""

import argparse
import json
import sys
import time

import cv2
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.data.keypoint_source import Detection2D
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.synth.sequence import HandTruth
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np

SEEDS = tuple(range(25000, 25008))
#: A detection matches a truth hand whose box it overlaps at least this much.
MATCH_IOU = 0.3
#: PCK threshold as a fraction of the truth box's longer side.
PCK_FRACTION = 0.2
TARGET_FOUND = 0.9
TARGET_PCK = 0.8
COUNTS = ('frames', 'visible', 'found', 'found_any', 'visible_whole', 'found_whole',
          'visible_overlapping', 'found_overlapping', 'pck_joints', 'pck_correct',
          'false_positives', 'scene_cuts')


def _size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` into (width, height)."""
    try:
        width, height = (int(part) for part in text.lower().split('x'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected WxH (e.g. 336x252), got {text!r}') from None
    return width, height


def _best_match(truth: HandTruth, detections: list[Detection2D],
                same_side: bool) -> Detection2D | None:
    """Return the detection overlapping the truth hand's box most (None below ``MATCH_IOU``)."""
    scored = [(box_iou(landmark_box(d.joints_2d), truth.box_xyxy), d) for d in detections
              if not same_side or d.side == truth.side]
    best = max(scored, key=lambda pair: pair[0], default=(0.0, None))
    return best[1] if best[0] >= MATCH_IOU else None


def _in_image(truth: HandTruth, width: int, height: int) -> np.ndarray:
    """Return the (21,) mask of truth joints inside the image and in front of the camera."""
    x, y = truth.joints_2d.T
    return (truth.joints_cam[:, 2] > 0) & (x >= 0) & (x < width) & (y >= 0) & (y < height)


def _score_frame(frame: SynthFrame, detections: list[Detection2D], counts: dict) -> None:
    """Add one frame's figures to ``counts``."""
    height, width = frame.rgb.shape[:2]
    visible = [truth for truth in frame.hands if truth.visible]
    counts['frames'] += 1
    for truth in visible:
        inside = _in_image(truth, width, height)
        whole = bool(inside.all())
        overlapping = whole and any(box_iou(truth.box_xyxy, other.box_xyxy) > 0
                                    for other in visible if other is not truth)
        match = _best_match(truth, detections, same_side=True)
        counts['visible'] += 1
        counts['visible_whole'] += whole
        counts['visible_overlapping'] += overlapping
        counts['found_any'] += _best_match(truth, detections, same_side=False) is not None
        if match is None:
            continue
        counts['found'] += 1
        counts['found_whole'] += whole
        counts['found_overlapping'] += overlapping
        box = truth.box_xyxy
        limit = PCK_FRACTION * max(box[2] - box[0], box[3] - box[1])
        error = np.linalg.norm(match.joints_2d - truth.joints_2d, axis=1)
        counts['pck_joints'] += int(inside.sum())
        counts['pck_correct'] += int((error[inside] <= limit).sum())
    counts['false_positives'] += sum(
        all(box_iou(landmark_box(d.joints_2d), t.box_xyxy) < MATCH_IOU for t in visible)
        for d in detections)


def _figures(counts: dict, times: list[float]) -> dict[str, object]:
    """Return the counts with their shares and MediaPipe's median ms/frame."""
    visible = max(counts['visible'], 1)
    isolated = counts['visible_whole'] - counts['visible_overlapping']
    found_isolated = counts['found_whole'] - counts['found_overlapping']
    return {**counts,
            'found_share': counts['found'] / visible,
            'found_any_share': counts['found_any'] / visible,
            'found_whole_share': counts['found_whole'] / max(counts['visible_whole'], 1),
            'found_cut_share': ((counts['found'] - counts['found_whole'])
                                / max(counts['visible'] - counts['visible_whole'], 1)),
            'found_overlapping_share': (counts['found_overlapping']
                                        / max(counts['visible_overlapping'], 1)),
            'found_isolated_share': found_isolated / max(isolated, 1),
            'found_ceiling_share': (counts['found'] + isolated - found_isolated) / visible,
            'pck': counts['pck_correct'] / counts['pck_joints'] if counts['pck_joints'] else None,
            'false_positives_per_frame': counts['false_positives'] / max(counts['frames'], 1),
            'mediapipe_ms_per_frame': 1e3 * float(np.median(times))}


def _draw(frame: SynthFrame, detections: list[Detection2D]) -> np.ndarray:
    """Return the frame (BGR) with truth boxes in green and detections in red."""
    image = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)
    marks = [(t.box_xyxy, SIDE_NAMES[t.side], (0, 200, 0)) for t in frame.hands if t.visible]
    marks += [(landmark_box(d.joints_2d), f'{SIDE_NAMES[d.side]} {d.confidence:.2f}',
               (0, 0, 255)) for d in detections]
    for box, label, colour in marks:
        x0, y0, x1, y1 = (int(round(v)) for v in box)
        cv2.rectangle(image, (x0, y0), (x1, y1), colour, 1)
        cv2.putText(image, label, (x0, max(y0 - 3, 9)), cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour)
    for detection in detections:
        for x, y in detection.joints_2d.round().astype(int):
            cv2.circle(image, (x, y), 1, (0, 0, 255), -1)
    return image


def _grid(tiles: list[np.ndarray], columns: int = 4) -> np.ndarray:
    """Return the tiles in rows of ``columns`` (blank tiles fill the last row)."""
    columns = min(columns, len(tiles))
    blank = np.zeros_like(tiles[0])
    tiles = tiles + [blank] * (-len(tiles) % columns)
    return np.vstack([np.hstack(tiles[i:i + columns]) for i in range(0, len(tiles), columns)])


def run(seeds: list[int], frames: int, size: tuple[int, int]) -> tuple[dict, list[np.ndarray]]:
    """Return the figures per seed and overall, and one annotated middle frame per seed."""
    config = HandsConfig(source='mediapipe', search_interval=1)  # MediaPipe as it is
    detector = MediaPipeDetector(config)
    synth = SynthConfig(width=size[0], height=size[1])
    report: dict[str, object] = {'size': f'{size[0]}x{size[1]}', 'frames_per_seed': frames,
                                 'targets': {'found_share': TARGET_FOUND, 'pck': TARGET_PCK},
                                 'seeds': {}}
    total = dict.fromkeys(COUNTS, 0)
    all_times: list[float] = []
    previews = []
    try:
        for seed in seeds:
            detector.reset()
            cuts = detector.scene_cuts
            counts = dict.fromkeys(COUNTS, 0)
            times = []
            for frame in SyntheticSequence(synth, seed=seed, num_frames=frames):
                start = time.perf_counter()
                found = detector.detect(frame.rgb, frame.index)
                times.append(time.perf_counter() - start)
                kept = [d for d in found if d.confidence >= config.min_confidence]
                _score_frame(frame, kept, counts)
                if frame.index == frames // 2:
                    previews.append(_draw(frame, kept))
            counts['scene_cuts'] = detector.scene_cuts - cuts
            report['seeds'][seed] = _figures(counts, times)
            total = {key: total[key] + counts[key] for key in COUNTS}
            all_times += times
    finally:
        detector.close()
    report['overall'] = _figures(total, all_times)
    return report, previews


def _percent(value: float | None) -> str:
    """Format a share as a percentage ('-' for none)."""
    return '-' if value is None else f'{100 * value:.1f}'


def _print(report: dict) -> None:
    """Print the report as a table."""
    print(f"MediaPipe Hands on synthetic sequences, {report['size']}, "
          f"{report['frames_per_seed']} frames per seed, both hands")
    print(f"{'seed':>8}{'visible':>8}{'found':>7}{'any':>6}{'found %':>9}{'any %':>7}"
          f"{'whole %':>9}{'cut %':>7}{'overlap %':>10}{'isol %':>8}{'ceil %':>8}{'PCK %':>7}"
          f"{'FP':>5}{'FP/fr':>7}"
          f"{'cuts':>6}{'ms/fr':>7}")
    rows = [*report['seeds'].items(), ('overall', report['overall'])]
    for name, row in rows:
        print(f"{name:>8}{row['visible']:>8}{row['found']:>7}{row['found_any']:>6}"
              f"{_percent(row['found_share']):>9}{_percent(row['found_any_share']):>7}"
              f"{_percent(row['found_whole_share']):>9}{_percent(row['found_cut_share']):>7}"
              f"{_percent(row['found_overlapping_share']):>10}"
              f"{_percent(row['found_isolated_share']):>8}"
              f"{_percent(row['found_ceiling_share']):>8}{_percent(row['pck']):>7}"
              f"{row['false_positives']:>5}{row['false_positives_per_frame']:>7.2f}"
              f"{row['scene_cuts']:>6}{row['mediapipe_ms_per_frame']:>7.1f}")
    print(f'targets: found (same side) >= {100 * TARGET_FOUND:.0f} %, '
          f'PCK@{PCK_FRACTION} >= {100 * TARGET_PCK:.0f} %; found among whole (all 21 joints in '
          'the image), cut (the others), overlapping (whole, box overlapping another) and '
          'isolated hands (whole, not overlapping); ceil: found if every isolated hand were')


def main() -> int:
    """Print the figures (or one JSON object)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=list(SEEDS),
                        help='synthetic sequence seeds (default 25000-25007)')
    parser.add_argument('--frames', type=int, default=60, help='frames per sequence')
    parser.add_argument('--size', type=_size, default=(336, 252),
                        help='image size WxH (336x252: the bundled model input; or 518x378)')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--save-preview', metavar='PATH',
                        help="write a PNG grid of each sequence's middle frame")
    args = parser.parse_args()
    if args.frames < 1:
        parser.error(f'--frames must be at least 1, got {args.frames}')
    cv2.setNumThreads(1)
    report, previews = run(args.seeds, args.frames, args.size)
    if args.save_preview and not cv2.imwrite(args.save_preview, _grid(previews)):
        parser.error(f'--save-preview: could not write {args.save_preview}')
    if args.json:
        print(json.dumps(report))
    else:
        _print(report)
    return 0


if __name__ == '__main__':
    sys.exit(main())
