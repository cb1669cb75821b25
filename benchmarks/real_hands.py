"""Hands on real pixels: each hand source against an independent detector, and its cost.

    python benchmarks/real_hands.py [--stills DIR] [--json]

Reads the shared real stills (``../shared/data/real_hands_stills``: 30 photos, one hand each)
and streams them through the engine with each hand source: ``mediapipe``, ``infinihand`` and
``infinihand`` with the ``verify`` guard (camera static, so only the hands differ). The
reference is MediaPipe in static-image mode, a separate instance (each photo on its own). It
prints, per source: the share of the reference's hands found (same side), phantom hands (a hand
the reference does not have, per frame), for mediapipe the share of hands whose lifted joints
reproject within 0.1 of the box size onto the landmarks, and the branch's presence scores.
The same for the mediapipe source on a continuous crop video of one still (panning and
zooming; the stills themselves are unrelated photos, a scene cut at every frame), whose
reference is the still's hand moved into each crop by the crop's exact transform. Then the cost
per frame on one torch thread: MediaPipe alone (its video mode as it is) beside the mediapipe
source (the engine's MediaPipe tracking + lifting to MANO), on the stills and on a crop video
of one still.
"""

import argparse
from dataclasses import replace
import json
from pathlib import Path
import sys
import time

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeConfig
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeKeypointSource
from infinihand_ros.engine.hands.mediapipe_source import MediaPipeHandSource
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.mano.builtin import BuiltinHandModel
import numpy as np
import torch

STILLS = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_hands_stills'
SOURCES = {'mediapipe': HandsConfig(source='mediapipe'),
           'infinihand': HandsConfig(source='infinihand'),
           'infinihand+verify': HandsConfig(source='infinihand', verify=True)}
#: A found hand matches a reference hand of the same side overlapping it at least this much.
MATCH_IOU = 0.3


def _reference(frames: list) -> list[list]:
    """Return the independent detector's hands per frame (static mode, one photo at a time)."""
    with MediaPipeKeypointSource(MediaPipeConfig(static_image_mode=True)) as detector:
        return [list(detector.detect(frame.rgb, index)) for index, frame in enumerate(frames)]


def _run_source(frames: list, hands: HandsConfig) -> tuple[list, dict]:
    """Return the engine's results per frame (static camera) and its hand statistics."""
    config = replace(load_engine_config(), hands=hands, camera_motion='static')
    with StreamingEngine(config) as engine:
        results = []
        for frame in frames:
            results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
        results += engine.flush()
        return results, engine.statistics['hands']


def _score(results: list, reference: list[list]) -> dict[str, object]:
    """Return found / phantom figures of one source against the reference."""
    found = phantoms = wanted = 0
    phantom_frames = 0
    for result, expected in zip(results, reference):
        wanted += len(expected)
        boxes = [(d.side, landmark_box(d.joints_2d)) for d in expected]
        frame_phantoms = 0
        for hand in result.hands:
            match = any(side == hand.side and box_iou(box, hand.box_xyxy) >= MATCH_IOU
                        for side, box in boxes)
            found += match
            frame_phantoms += not match
        phantoms += frame_phantoms
        phantom_frames += frame_phantoms > 0
    return {'reference_hands': wanted, 'found': found,
            'found_share': found / max(wanted, 1), 'phantom_hands': phantoms,
            'phantom_frame_share': phantom_frames / max(len(results), 1)}


def _crop_video(frame, count: int = 60) -> list:
    """Return a crop video (panning, zooming) of one still: (RGB, exact intrinsics, affine).

    The affine (2, 3) maps the still's pixels to the crop's, so the still's hand is known in
    every crop.
    """
    import cv2
    k = frame.intrinsics
    out = []
    for index in range(count):
        phase = index / count
        width = 640 * (0.55 + 0.25 * np.sin(2 * np.pi * phase))
        x0 = (640 - width) * (0.5 + 0.4 * np.sin(2 * np.pi * phase))
        y0 = (480 - width * 0.75) * 0.5
        scale = 320 / width
        matrix = np.array([[scale, 0.0, (0.5 - x0) * scale - 0.5],
                           [0.0, scale, (0.5 - y0) * scale - 0.5]])
        rgb = cv2.warpAffine(frame.rgb, matrix, (320, 240), flags=cv2.INTER_AREA)
        intrinsics = Intrinsics(k.fx * scale, k.fy * scale, (k.cx + 0.5 - x0) * scale - 0.5,
                                (k.cy + 0.5 - y0) * scale - 0.5, 320, 240)
        out.append((rgb, intrinsics, matrix))
    return out


def _moved_reference(still_hands: list, crops: list) -> list[list]:
    """Return the still's hands moved into each crop (kept where most of the box is in view)."""
    moved = []
    for rgb, _, matrix in crops:
        inside = []
        for hand in still_hands:
            joints = hand.joints_2d @ matrix[:, :2].T + matrix[:, 2]
            box = landmark_box(joints)
            view = np.array([0.0, 0.0, rgb.shape[1], rgb.shape[0]])
            area = (box[2] - box[0]) * (box[3] - box[1])
            clipped = np.concatenate([np.maximum(box[:2], view[:2]),
                                      np.minimum(box[2:], view[2:])])
            seen = max(0.0, clipped[2] - clipped[0]) * max(0.0, clipped[3] - clipped[1])
            if area > 0 and seen / area >= 0.5:
                inside.append(replace(hand, joints_2d=joints))
        moved.append(inside)
    return moved


def _costs(images: list[tuple[np.ndarray, Intrinsics]]) -> dict[str, float]:
    """Return ms per frame of MediaPipe alone and of the mediapipe source.

    Over all frames (median, mean) and over the frames where each found one hand (median).
    MediaPipe alone is its video mode as it is (``hands.search_interval: 1``); the source is
    the engine's default (one hand tracked alone, a second one searched for at intervals) with
    the lifting to MANO.
    """
    torch.set_num_threads(1)
    config = HandsConfig(source='mediapipe')
    detector = MediaPipeDetector(replace(config, search_interval=1))
    source = MediaPipeHandSource(config, (BuiltinHandModel(0), BuiltinHandModel(1)))
    times: dict[str, list[tuple[float, int]]] = {}
    try:
        for _ in range(2):  # the first round warms both up
            times = {'mediapipe_alone': [], 'mediapipe_source': []}
            for index, (rgb, intrinsics) in enumerate(images):
                start = time.perf_counter()
                found = detector.detect(rgb, index)
                times['mediapipe_alone'].append((time.perf_counter() - start, len(found)))
                start = time.perf_counter()
                found = source.camera_hands(source.detect(rgb, index), (), intrinsics)
                times['mediapipe_source'].append((time.perf_counter() - start, len(found)))
    finally:
        detector.close()
        source.close()
    report = {}
    for name, rows in times.items():
        seconds, hands = np.array(rows).T
        report |= {f'{name}_ms': 1e3 * float(np.median(seconds)),
                   f'{name}_mean_ms': 1e3 * float(np.mean(seconds)),
                   f'{name}_one_hand_ms': 1e3 * float(np.median(seconds[hands == 1]))
                   if np.any(hands == 1) else float('nan'),
                   f'{name}_hands_per_frame': float(hands.mean())}
    report['ratio'] = report['mediapipe_source_ms'] / report['mediapipe_alone_ms']
    return report


def main() -> int:
    """Print the figures (or one JSON object)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--stills', type=Path, default=STILLS, help='the real stills bag')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    args = parser.parse_args()
    if not args.stills.exists():
        parser.error(f'{args.stills} does not exist (the shared real stills)')
    frames = list(read_camera_frames(args.stills))
    reference = _reference(frames)
    report: dict[str, object] = {'frames': len(frames),
                                 'reference_frames_with_hands': sum(map(bool, reference))}
    for name, hands in SOURCES.items():
        results, statistics = _run_source(frames, hands)
        report[name] = {**_score(results, reference), 'statistics': statistics}
        if name == 'infinihand':
            scores = [h.confidence for r in results for h in r.hands]
            report[name]['presence_percentiles_10_50_90'] = (
                np.percentile(scores, [10, 50, 90]).round(3).tolist() if scores else [])
    single = next(f for f, r in zip(frames, reference) if len(r) == 1)
    video = _crop_video(single)
    crops = [replace(single, rgb=rgb, intrinsics=k, timestamp_ns=index * 100_000_000)
             for index, (rgb, k, _) in enumerate(video)]
    crop_results, statistics = _run_source(crops, SOURCES['mediapipe'])
    still_hands = reference[frames.index(single)]
    moved = _moved_reference(still_hands, video)
    report['mediapipe_crop_video'] = {**_score(crop_results, moved),
                                      'statistics': statistics}
    report['cost_stills'] = _costs([(f.rgb, f.intrinsics) for f in frames])
    report['cost_crop_video'] = _costs([(rgb, k) for rgb, k, _ in video])
    if args.json:
        print(json.dumps(report, indent=2, default=float))
        return 0
    print(f"{report['frames']} real stills; the reference (MediaPipe, static mode) has hands on "
          f"{report['reference_frames_with_hands']}")
    print(f"{'source':<20}{'found':>8}{'share':>8}{'phantom hands':>15}{'phantom frames':>16}")
    for name in [*SOURCES, 'mediapipe_crop_video']:
        row = report[name]
        print(f"{name:<20}{row['found']:>8}{row['found_share']:>8.3f}{row['phantom_hands']:>15}"
              f"{row['phantom_frame_share']:>16.3f}")
    print(f'mediapipe: lifted joints within 0.1 of the box (p95 of the error as a box '
          f"fraction): {report['mediapipe']['statistics']['reprojection_box_fraction_p95']:.3f}")
    print(f'infinihand presence scores (10/50/90 %): '
          f"{report['infinihand']['presence_percentiles_10_50_90']}")
    for key in ('cost_stills', 'cost_crop_video'):
        cost = report[key]
        print(f'{key} (ms per frame: median / mean / median on frames with one hand): '
              f"MediaPipe alone {cost['mediapipe_alone_ms']:.1f} / "
              f"{cost['mediapipe_alone_mean_ms']:.1f} / {cost['mediapipe_alone_one_hand_ms']:.1f}"
              f" ({cost['mediapipe_alone_hands_per_frame']:.2f} hands/frame), mediapipe source "
              f"{cost['mediapipe_source_ms']:.1f} / {cost['mediapipe_source_mean_ms']:.1f} / "
              f"{cost['mediapipe_source_one_hand_ms']:.1f} "
              f"({cost['mediapipe_source_hands_per_frame']:.2f} hands/frame); ratio of medians "
              f"{cost['ratio']:.2f}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
