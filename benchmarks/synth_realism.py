"""Realism of the synthetic hands: how many MediaPipe Hands finds and how well it agrees.

    python benchmarks/synth_realism.py [--seeds 25000 ... 25007] [--frames 60] [--size 336x252]
        [--stills DIR] [--real-stills N] [--json] [--save-preview PATH]

Generates synthetic sequences (both hands; by default seeds 25000-25007, a range no training or
evaluation set uses) and runs MediaPipe Hands on them as it is (``MEDIAPIPE``: video mode, its palm
detector whenever it tracks fewer than two hands, its own default tracking confidence; ``reset``
between sequences, detections scoring at least ``hands.min_confidence``). A visible truth hand (at
least ``synth.min_visible_px`` pixels in view) is found when a detection of the same side overlaps
its box (IoU of the detection's landmark box with the truth's mask box at least 0.3); found
regardless of side is counted apart (side swaps). Whole hands are the visible ones whose 21 joints
all lie in the image, cut hands the others; overlapping hands are whole hands whose box overlaps
another visible hand's, isolated hands the whole ones that overlap no other. PCK@0.2 over the found
hands: the share of their truth joints inside the image (and in front of the camera) whose
detection lies within 0.2 of the truth box's longer side. A detection overlapping no visible truth
hand (either side) is a false positive. Prints per seed and overall, beside the realism targets
(found >= 90 %, PCK@0.2 >= 80 %), with MediaPipe's median ms/frame.

Then the real reference: the found share by the number of joints in the image, for the synthetic
hands overlapping no other hand and for real hands cut the same way. Each hand MediaPipe finds
in the shared real stills (``../shared/data/real_hands_stills``, static mode, the whole photo) is
filmed by a crop window (``PAN_CROP_BOXES`` times the hand's box, the benchmark's image size)
panning until the hand has left through one border, for each border: the frames in order (the
hand leaving, tracked) and reversed (the hand entering, found afresh), MediaPipe as above; its
truth is the reference's landmarks moved into each crop, its box their box clipped to the image.
Skipped when the stills are absent (``--real-stills 0`` skips it). Both tables give the share
found regardless of side beside it: the real hands' side is MediaPipe's own on the whole photo,
so only the synthetic hands' side is checked against the truth. Last, the whole hands by the
side the camera sees (``VIEW_BINS``: the back of the hand, obliquely, edge-on or the palm): the
synthetic ones overlapping no other, and the real frames showing the whole hand (its view from
MediaPipe's metric landmarks on the whole photo).
``--save-preview`` writes a PNG grid of each sequence's middle frame: truth boxes green, detections
red. Figures only; nothing is asserted.
"""

import argparse
import json
from pathlib import Path
import sys
import time

import cv2
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeConfig
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeKeypointSource
from infinihand_ros.mano.capsules import palm_axes
from infinihand_ros.mano.capsules import PALM_JOINTS
from infinihand_ros.synth.photo_streams import crop_stream
from infinihand_ros.synth.sequence import HandTruth
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np

SEEDS = tuple(range(25000, 25008))
#: MediaPipe Hands with its own defaults: every frame searched while fewer than two hands are
#: tracked, a hand re-detected where its landmark score falls under 0.5 (the engine: 0.8).
MEDIAPIPE = HandsConfig(source='mediapipe', search_interval=1, min_tracking_confidence=0.5)
STILLS = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_hands_stills'
#: A detection matches a truth hand whose box it overlaps at least this much.
MATCH_IOU = 0.3
#: PCK threshold as a fraction of the truth box's longer side.
PCK_FRACTION = 0.2
TARGET_FOUND = 0.9
TARGET_PCK = 0.8
#: Bins of the number of a hand's joints inside the image (lowest, highest), whole hands first.
JOINT_BINS = ((21, 21), (19, 20), (16, 18), (10, 15), (1, 9))
#: Views of a hand: the cosine of its palm normal (palm side out) with the ray to its palm, at
#: least the bin's lower bound (positive: the back of the hand faces the camera), back first.
VIEW_BINS = (('back', 0.6), ('back, oblique', 0.3), ('edge-on', -0.3), ('palm', -1.0))
#: The real reference's crop window, in multiples of the hand's landmark box (longer side), and
#: the frames of a pan from the hand centred to the hand gone.
PAN_CROP_BOXES = 3.5
PAN_STEPS = 20
#: Directions (x, y) the window moves the hand in: out through the bottom, top, right, left.
PAN_BORDERS = ((0, 1), (0, -1), (1, 0), (-1, 0))
COUNTS = ('frames', 'visible', 'found', 'found_any', 'visible_whole', 'found_whole',
          'visible_overlapping', 'found_overlapping', 'pck_joints', 'pck_correct',
          'false_positives', 'scene_cuts')


def _bin_label(low: int, high: int) -> str:
    """Return a joint bin's label ('21', '19-20', ...)."""
    return str(low) if low == high else f'{low}-{high}'


def _joint_bin(count: int) -> str | None:
    """Return the label of the bin holding ``count`` joints in the image (None for 0)."""
    return next((_bin_label(low, high) for low, high in JOINT_BINS if low <= count <= high),
                None)


def _bin_counts() -> dict[str, list[int]]:
    """Return empty [hands, found, found regardless of side] counts per joint bin."""
    return {_bin_label(low, high): [0, 0, 0] for low, high in JOINT_BINS}


def _view_counts() -> dict[str, list[int]]:
    """Return empty [hands, found, found regardless of side] counts per view."""
    return {label: [0, 0, 0] for label, _ in VIEW_BINS}


def _tally(table: dict[str, list[int]], key: str | None, outcome: tuple[int, bool, bool]) -> None:
    """Add (1, found, found regardless of side) to ``table[key]``; nothing for a None key."""
    if key is not None:
        table[key] = [total + add for total, add in zip(table[key], outcome)]


def _view(joints: np.ndarray, side: int, ray: np.ndarray) -> str:
    """Return the ``VIEW_BINS`` label of the side of a hand seen along ``ray`` (3,).

    ``joints`` (21, 3) may be in any frame whose axes are the camera's.
    """
    cosine = palm_axes(joints, side)[2] @ ray / np.linalg.norm(ray)
    return next(label for label, low in VIEW_BINS if cosine >= low)


def _truth_view(truth: HandTruth) -> str:
    """Return the view of a truth hand from its camera (the ray to its palm's middle)."""
    return _view(truth.joints_cam, truth.side, truth.joints_cam[list(PALM_JOINTS)].mean(axis=0))


def _size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` into (width, height)."""
    try:
        width, height = (int(part) for part in text.lower().split('x'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected WxH (e.g. 336x252), got {text!r}') from None
    return width, height


def _best_match(box: np.ndarray, side: int, detections: list[Detection2D],
                same_side: bool) -> Detection2D | None:
    """Return the detection overlapping a truth box most (None below ``MATCH_IOU``)."""
    scored = [(box_iou(landmark_box(d.joints_2d), box), d) for d in detections
              if not same_side or d.side == side]
    best = max(scored, key=lambda pair: pair[0], default=(0.0, None))
    return best[1] if best[0] >= MATCH_IOU else None


def _in_image(truth: HandTruth, width: int, height: int) -> np.ndarray:
    """Return the (21,) mask of truth joints inside the image and in front of the camera."""
    x, y = truth.joints_2d.T
    return (truth.joints_cam[:, 2] > 0) & (x >= 0) & (x < width) & (y >= 0) & (y < height)


def _score_frame(frame: SynthFrame, detections: list[Detection2D], counts: dict,
                 bins: dict[str, list[int]], views: dict[str, list[int]]) -> None:
    """Add one frame's figures to ``counts``, its hands overlapping no other to ``bins``.

    Those also whole go to ``views`` too.
    """
    height, width = frame.rgb.shape[:2]
    visible = [truth for truth in frame.hands if truth.visible]
    counts['frames'] += 1
    for truth in visible:
        inside = _in_image(truth, width, height)
        whole = bool(inside.all())
        alone = not any(box_iou(truth.box_xyxy, other.box_xyxy) > 0
                        for other in visible if other is not truth)
        overlapping = whole and not alone
        match = _best_match(truth.box_xyxy, truth.side, detections, same_side=True)
        any_side = _best_match(truth.box_xyxy, truth.side, detections,
                               same_side=False) is not None
        label = _joint_bin(int(inside.sum()))
        outcome = (1, match is not None, any_side)
        _tally(bins, label if alone else None, outcome)
        _tally(views, _truth_view(truth) if alone and whole else None, outcome)
        counts['visible'] += 1
        counts['visible_whole'] += whole
        counts['visible_overlapping'] += overlapping
        counts['found_any'] += any_side
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
    """Return the figures per seed and overall, and one annotated middle frame per seed.

    ``report['joint_bins']`` holds [hands, found, found regardless of side] per joint bin of the
    hands overlapping no other, ``report['views']`` the same per view of the whole ones.
    """
    detector = MediaPipeDetector(MEDIAPIPE)
    synth = SynthConfig(width=size[0], height=size[1])
    report: dict[str, object] = {'size': f'{size[0]}x{size[1]}', 'frames_per_seed': frames,
                                 'targets': {'found_share': TARGET_FOUND, 'pck': TARGET_PCK},
                                 'seeds': {}}
    total = dict.fromkeys(COUNTS, 0)
    bins = _bin_counts()
    views = _view_counts()
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
                kept = [d for d in found if d.confidence >= MEDIAPIPE.min_confidence]
                _score_frame(frame, kept, counts, bins, views)
                if frame.index == frames // 2:
                    previews.append(_draw(frame, kept))
            counts['scene_cuts'] = detector.scene_cuts - cuts
            report['seeds'][seed] = _figures(counts, times)
            total = {key: total[key] + counts[key] for key in COUNTS}
            all_times += times
    finally:
        detector.close()
    report['overall'] = _figures(total, all_times)
    report['joint_bins'] = bins
    report['views'] = views
    return report, previews


def pan_windows(box: np.ndarray, direction: tuple[int, int], photo_size: tuple[int, int],
                size: tuple[int, int]) -> tuple[np.ndarray, float]:
    """Return the centres (N, 2) and the width of a crop window moving a hand out of view.

    The window (``PAN_CROP_BOXES`` times the box's longer side, the aspect of ``size``) starts
    centred on the box and moves against ``direction`` until the whole box has left through
    that border (by half its side or more); the pan stops where the window would leave the
    photo.
    """
    side = float(max(box[2] - box[0], box[3] - box[1]))
    width = PAN_CROP_BOXES * side
    half = 0.5 * np.array([width, width * size[1] / size[0]])
    step = np.asarray(direction, float)
    travel = float(half @ np.abs(step)) + side
    centres = (0.5 * (box[:2] + box[2:])
               - np.outer(np.linspace(0.0, travel, PAN_STEPS), step))
    inside = np.all((centres - half >= 0) & (centres + half <= photo_size), axis=1)
    stop = len(centres) if inside.all() else int(np.argmin(inside))  # the first window outside
    return centres[:stop], width


def crop_joints(joints: np.ndarray, photo_k: Intrinsics, crop_k: Intrinsics) -> np.ndarray:
    """Return photo pixels (N, 2) moved into a crop with intrinsics ``crop_k`` (same camera)."""
    scale = np.array([crop_k.fx / photo_k.fx, crop_k.fy / photo_k.fy])
    return (joints - [photo_k.cx, photo_k.cy]) * scale + [crop_k.cx, crop_k.cy]


def real_reference(stills: Path, limit: int | None,
                   size: tuple[int, int]) -> dict[str, dict[str, list[int]]]:
    """Return [hands, found, found regardless of side] per joint bin and per view of real hands.

    Per joint bin for the hands leaving and entering the image, per view for the frames that
    show them whole (both pans). A real hand's side is MediaPipe's on the whole photo, its view
    that of MediaPipe's metric landmarks there.
    """
    photos = list(read_camera_frames(stills))[:limit]
    with MediaPipeKeypointSource(MediaPipeConfig(static_image_mode=True)) as reference:
        hands = [(photo, hand) for index, photo in enumerate(photos)
                 for hand in reference.detect(photo.rgb, index)
                 if hand.confidence >= MEDIAPIPE.min_confidence]
    bins = {'leaving': _bin_counts(), 'entering': _bin_counts(), 'views': _view_counts()}
    detector = MediaPipeDetector(MEDIAPIPE)
    try:
        for photo, hand in hands:
            photo_size = (photo.rgb.shape[1], photo.rgb.shape[0])
            palm = hand.joints_2d[list(PALM_JOINTS)].mean(axis=0)
            view = _view(hand.joints_metric, hand.side,
                         np.linalg.solve(photo.intrinsics.matrix(), [*palm, 1.0]))
            for direction in PAN_BORDERS:
                centres, width = pan_windows(landmark_box(hand.joints_2d), direction,
                                             photo_size, size)
                crops = crop_stream(photo.rgb, photo.intrinsics, centres,
                                    np.full(len(centres), width), size)
                truths = []  # per crop: the hand's joint bin and its box clipped to the image
                for crop in crops:
                    joints = crop_joints(hand.joints_2d, photo.intrinsics, crop.intrinsics)
                    inside = np.all((joints >= 0) & (joints < size), axis=1)
                    truths.append((_joint_bin(int(inside.sum())),
                                   np.clip(landmark_box(joints), 0, [*size, *size])))
                pairs = list(zip(crops, truths))
                for name, order in (('leaving', pairs), ('entering', pairs[::-1])):
                    detector.reset()
                    for index, (crop, (label, box)) in enumerate(order):
                        found = [d for d in detector.detect(crop.rgb, index)
                                 if d.confidence >= MEDIAPIPE.min_confidence]
                        outcome = (1, _best_match(box, hand.side, found, True) is not None,
                                   _best_match(box, hand.side, found, False) is not None)
                        _tally(bins[name], label, outcome)
                        _tally(bins['views'], view if label == '21' else None, outcome)
    finally:
        detector.close()
    return bins


def _percent(value: float | None) -> str:
    """Format a share as a percentage ('-' for none)."""
    return '-' if value is None else f'{100 * value:.1f}'


def _share(counts: list[int]) -> str:
    """Format [hands, found, found regardless of side] as 'found % / any side % (hands)'."""
    hands, found, found_any = counts
    shares = (_percent(found / hands), _percent(found_any / hands)) if hands else ('-', '-')
    return f'{shares[0]:>5} /{shares[1]:>5} ({hands:>4})'


def _print(report: dict) -> None:
    """Print the report as tables."""
    print(f"MediaPipe Hands on synthetic sequences, {report['size']}, "
          f"{report['frames_per_seed']} frames per seed, both hands")
    print(f"{'seed':>8}{'visible':>8}{'found':>7}{'any':>6}{'found %':>9}{'any %':>7}"
          f"{'whole %':>9}{'cut %':>7}{'overlap %':>10}{'isol %':>8}{'PCK %':>7}"
          f"{'FP':>5}{'FP/fr':>7}"
          f"{'cuts':>6}{'ms/fr':>7}")
    rows = [*report['seeds'].items(), ('overall', report['overall'])]
    for name, row in rows:
        print(f"{name:>8}{row['visible']:>8}{row['found']:>7}{row['found_any']:>6}"
              f"{_percent(row['found_share']):>9}{_percent(row['found_any_share']):>7}"
              f"{_percent(row['found_whole_share']):>9}{_percent(row['found_cut_share']):>7}"
              f"{_percent(row['found_overlapping_share']):>10}"
              f"{_percent(row['found_isolated_share']):>8}{_percent(row['pck']):>7}"
              f"{row['false_positives']:>5}{row['false_positives_per_frame']:>7.2f}"
              f"{row['scene_cuts']:>6}{row['mediapipe_ms_per_frame']:>7.1f}")
    print(f'targets: found (same side) >= {100 * TARGET_FOUND:.0f} %, '
          f'PCK@{PCK_FRACTION} >= {100 * TARGET_PCK:.0f} %; found among whole (all 21 joints in '
          'the image), cut (the others), overlapping (whole, box overlapping another) and '
          'isolated hands (whole, not overlapping)')
    real = report.get('real_reference')
    print('\nfound % / found regardless of side % (hands) by joints in the image, hands '
          'overlapping no other: synthetic, '
          + ('and real stills panned out of view (leaving) and into it (entering; their side: '
             "MediaPipe's on the whole photo)" if real
             else 'no real reference (stills absent or --real-stills 0)'))
    print(f"{'joints':>7}{'synthetic':>22}" + (f"{'real leaving':>23}{'real entering':>23}"
                                               if real else ''))
    for label, counts in report['joint_bins'].items():
        print(f'{label:>7}{_share(counts):>22}' + (
            f"{_share(real['leaving'][label]):>23}{_share(real['entering'][label]):>23}"
            if real else ''))
    print('\nfound % / found regardless of side % (hands) by the side of the hand the camera '
          'sees (cosine of the palm normal with the ray: back >= 0.6 > oblique >= 0.3 > edge-on '
          '>= -0.3 > palm), whole hands overlapping no other: synthetic'
          + (', and the real frames showing the whole hand (both pans)' if real else ''))
    print(f"{'view':>14}{'synthetic':>22}" + (f"{'real':>23}" if real else ''))
    for label, counts in report['views'].items():
        print(f'{label:>14}{_share(counts):>22}'
              + (f"{_share(real['views'][label]):>23}" if real else ''))


def main() -> int:
    """Print the figures (or one JSON object)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=list(SEEDS),
                        help='synthetic sequence seeds (default 25000-25007)')
    parser.add_argument('--frames', type=int, default=60, help='frames per sequence')
    parser.add_argument('--size', type=_size, default=(336, 252),
                        help='image size WxH (336x252: the bundled model input; or 518x378)')
    parser.add_argument('--stills', type=Path, default=STILLS,
                        help='the real stills bag (default ../shared/data/real_hands_stills)')
    parser.add_argument('--real-stills', type=int, default=None, metavar='N',
                        help='pan the hands of the first N stills (default all; 0: no reference)')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--save-preview', metavar='PATH',
                        help="write a PNG grid of each sequence's middle frame")
    args = parser.parse_args()
    if args.frames < 1:
        parser.error(f'--frames must be at least 1, got {args.frames}')
    if args.real_stills is not None and args.real_stills < 0:
        parser.error(f'--real-stills must be at least 0, got {args.real_stills}')
    cv2.setNumThreads(1)
    report, previews = run(args.seeds, args.frames, args.size)
    if args.real_stills != 0 and args.stills.exists():
        report['real_reference'] = real_reference(args.stills, args.real_stills, args.size)
    if args.save_preview and not cv2.imwrite(args.save_preview, _grid(previews)):
        parser.error(f'--save-preview: could not write {args.save_preview}')
    if args.json:
        print(json.dumps(report))
    else:
        _print(report)
    return 0


if __name__ == '__main__':
    sys.exit(main())
