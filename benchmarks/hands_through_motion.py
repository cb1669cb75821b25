"""Our MediaPipe hand detector through fast turns, motion blur and hands lost for a while.

    python benchmarks/hands_through_motion.py [--photos N] [--json]

Real-texture streams (``synth/motion_streams.py``) from ``../shared/data``: crop videos of real
hand photos (``--photos`` of them) turning fast to and fro (0.3 of the view per frame, blurred
over half the shift) and turning away from the hand for four frames and back; the ego4d_stove
clip as it is, with eight frames motion-blurred (15 or 31 px), with its hands removed on five
frames and with one of them removed on four; ego4d_counter at every fourth frame (a fast pan),
each frame blurred 31 px. Each stream runs through our detector
(``engine/hands/mediapipe_detector.py``, the engine's settings) and MediaPipe alone (video
mode, two hands, on every frame). Per kind of stream: the scene cuts our detector declares
(none of these streams has one), hands found (summed over frames) by ours and by MediaPipe
alone, frames where MediaPipe alone finds more, and per stream with a loss the frames from the
hands' return until a frame has as many hands as MediaPipe alone finds there without the loss
(0: at once).
"""

import argparse
from dataclasses import dataclass
import json
from pathlib import Path

import cv2
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeConfig
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeKeypointSource
from infinihand_ros.eval.reference_clip import mediapipe_labelled
from infinihand_ros.synth.motion_streams import blurred_run
from infinihand_ros.synth.motion_streams import hands_hidden
from infinihand_ros.synth.motion_streams import panned_away
from infinihand_ros.synth.motion_streams import shaken_crops
import numpy as np

DATA = Path(__file__).resolve().parents[2] / 'shared' / 'data'
#: Hands removed on ego4d_stove frames 20-24; one hand on frames 12-15 (the right one) or 40-43
#: (the left one); the photo turned away on its frames 4-7.
HIDDEN = (20, 5)
ONE_HIDDEN = (12, 4, 40)
AWAY = (4, 4)


@dataclass(frozen=True)
class Stream:
    """A stream of RGB frames.

    Attributes:
        frames: RGB uint8 images.
        return_at: the frame where lost hands come back (None: no loss).
        unaltered: the same frames without the loss (what the hands are counted against).

    """

    frames: list[np.ndarray]
    return_at: int | None = None
    unaltered: list[np.ndarray] | None = None


def _clip(name: str) -> list[np.ndarray]:
    files = sorted((DATA / 'real_ego' / name / 'frames').glob('*.jpg'))
    return [cv2.cvtColor(cv2.imread(str(file)), cv2.COLOR_BGR2RGB) for file in files]


def _one_hand_photos(count: int) -> list[tuple]:
    """Return the first stills where MediaPipe finds one confident hand, with its landmarks."""
    photos = []
    with MediaPipeKeypointSource(MediaPipeConfig(max_num_hands=2)) as mediapipe:
        for frame in read_camera_frames(DATA / 'real_hands_stills'):
            found = mediapipe.detect(frame.rgb, 0)
            if len(found) == 1 and found[0].confidence > 0.9:
                photos.append((frame, found[0].joints_2d))
            if len(photos) == count:
                break
    return photos


def _one_side(hands: list[list[np.ndarray]], right: bool) -> list[list[np.ndarray]]:
    """Return per frame the hand on the image's right (or left) half, if any (384 px wide)."""
    return [[joints for joints in frame if (joints[:, 0].mean() > 192) == right][:1]
            for frame in hands]


def streams(photos: int) -> dict[str, list[Stream]]:
    """Return the benchmark's streams by kind (see the module docstring)."""
    stills = _one_hand_photos(photos)
    stove, counter = _clip('ego4d_stove'), _clip('ego4d_counter')
    stove_hands = [[joints for _, joints in hands]
                   for hands in mediapipe_labelled(DATA / 'real_ego' / 'ego4d_stove')]
    turned = [[f.rgb for f in panned_away(photo.rgb, photo.intrinsics, hand, *AWAY)]
              for photo, hand in stills]
    return {
        f'{photos} photos, fast turns (0.3 of the view per frame)': [
            Stream([f.rgb for f in shaken_crops(photo.rgb, photo.intrinsics, hand, blur=0.5)])
            for photo, hand in stills],
        f'{photos} photos, turned away {AWAY[1]} frames': [
            Stream(frames, sum(AWAY), [frames[0]] * len(frames)) for frames in turned],
        'ego4d_stove': [Stream(stove)],
        'ego4d_stove, 8 frames blurred 15 px': [Stream(blurred_run(stove, 20, 8, 15, 20.0))],
        'ego4d_stove, 8 frames blurred 31 px': [Stream(blurred_run(stove, 20, 8, 31, 20.0))],
        f'ego4d_stove, hands hidden {HIDDEN[1]} frames': [
            Stream(hands_hidden(stove, stove_hands, *HIDDEN), sum(HIDDEN), stove)],
        f'ego4d_stove, one hand hidden {ONE_HIDDEN[1]} frames (right at {ONE_HIDDEN[0]}, '
        f'left at {ONE_HIDDEN[2]})': [
            Stream(hands_hidden(stove, _one_side(stove_hands, right), start, ONE_HIDDEN[1]),
                   start + ONE_HIDDEN[1], stove)
            for right, start in ((True, ONE_HIDDEN[0]), (False, ONE_HIDDEN[2]))],
        'ego4d_counter, every 4th frame, blurred 31 px': [
            Stream(blurred_run(counter[::4], 0, len(counter[::4]), 31))]}


def mediapipe_alone(frames: list[np.ndarray]) -> list[int]:
    """Return the hands MediaPipe alone (video mode, two hands) finds per frame."""
    with MediaPipeKeypointSource(MediaPipeConfig(max_num_hands=2,
                                                 static_image_mode=False)) as alone:
        return [len(alone.detect(image, index)) for index, image in enumerate(frames)]


def ours(frames: list[np.ndarray]) -> tuple[list[int], list[int]]:
    """Return the hands our detector finds per frame, and the frames it declares cuts at."""
    detector = MediaPipeDetector(HandsConfig(source='mediapipe'))
    counts, cuts = [], []
    try:
        for index, image in enumerate(frames):
            counts.append(len(detector.detect(image, index)))
            cuts += [index] if detector.cut else []
    finally:
        detector.close()
    return counts, cuts


def frames_to_refind(counts: list[int], expected: list[int], return_at: int) -> int | None:
    """Return the frames from ``return_at`` until a frame has its ``expected`` hands (None: never).

    Only frames where hands are expected count.
    """
    later = [k for k, (count, wanted) in enumerate(zip(counts[return_at:], expected[return_at:]))
             if wanted and count >= wanted]
    return later[0] if later else None


def score(name: str, group: list[Stream]) -> dict:
    """Return the figures of a kind of stream, summed over its streams."""
    report = {'streams': name, 'frames': 0, 'cuts': 0, 'ours': 0, 'alone': 0, 'alone_more': 0,
              'refound_ours': [], 'refound_alone': []}
    for stream in group:
        found, cuts = ours(stream.frames)
        alone = mediapipe_alone(stream.frames)
        report['frames'] += len(found)
        report['cuts'] += len(cuts)
        report['ours'] += sum(found)
        report['alone'] += sum(alone)
        report['alone_more'] += sum(b > a for a, b in zip(found, alone))
        if stream.return_at is not None:
            expected = mediapipe_alone(stream.unaltered)
            report['refound_ours'].append(frames_to_refind(found, expected, stream.return_at))
            report['refound_alone'].append(frames_to_refind(alone, expected, stream.return_at))
    return report


def main() -> None:
    """Print one row per kind of stream."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--photos', type=int, default=6, help='photos per photo stream kind')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f'{DATA} is absent: the streams are made from its real frames')
    reports = [score(name, group) for name, group in streams(args.photos).items()]
    if args.json:
        print(json.dumps(reports))
        return
    print('| streams | frames | scene cuts | hands found: ours / MediaPipe alone | '
          'frames where MediaPipe alone finds more | frames to find the hands again: ours / '
          'alone |')
    print('|---|---|---|---|---|---|')
    for r in reports:
        print(f"| {r['streams']} | {r['frames']} | {r['cuts']} | {r['ours']} / {r['alone']} | "
              f"{r['alone_more']} | {r['refound_ours'] or ''} / {r['refound_alone'] or ''} |")


if __name__ == '__main__':
    main()
