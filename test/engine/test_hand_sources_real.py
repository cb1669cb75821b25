"""The MediaPipe hand source on real pixels (../shared/data stills; skipped when absent).

Real photos, and crop "videos" of them whose intrinsics are exact
(``synth/photo_streams.py``): the hand's camera-frame position is the same in every crop, so
the stream path, identity and smoothing are checked against a known answer on real pixels.
"""

from dataclasses import replace

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import OPENPOSE_TO_MANO
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.engine.hands.mediapipe_source import MediaPipeHandSource
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.kinematics import PARENTS_WITH_TIPS
from infinihand_ros.synth.photo_streams import crop_stream
from infinihand_ros.synth.photo_streams import hand_and_arm_patch
from infinihand_ros.synth.photo_streams import pasted_stream
import numpy as np
import pytest
from real_stills import require_stills

MODELS = (BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT))


@pytest.fixture(scope='module')
def stills() -> list:
    """Return the 30 real photos (skips when the shared data is absent)."""
    return require_stills()


def _source(**settings: object) -> MediaPipeHandSource:
    return MediaPipeHandSource(HandsConfig(source='mediapipe', **settings), MODELS)


def _still_hands(source: MediaPipeHandSource, frame) -> tuple:
    """Detect on one still as a new stream (the photos are unrelated)."""
    source.reset()
    detections = source.detect(frame.rgb, 0)
    return source.camera_hands(detections, (), frame.intrinsics)


def _bone_lengths(joints: np.ndarray) -> np.ndarray:
    mano = joints[list(OPENPOSE_TO_MANO)]
    parents = np.array(PARENTS_WITH_TIPS[1:])
    return np.linalg.norm(mano[1:] - mano[parents], axis=1)


def test_real_stills_hands_found_lifted_onto_their_landmarks(stills: list) -> None:
    """Find the hand in most photos; lifted hands reproject within 0.1 of the box.

    Wrist depths lie in front of the camera: 0.15-3 m (the stills' fx = 500 is not their
    lens's, and the photos were downscaled into 640x480, so people at arm's length from the
    lens look up to about 3 m away). Bone lengths are the same in every hand (one shape).
    """
    source = _source()
    try:
        per_frame = [_still_hands(source, frame) for frame in stills]
        ratios = source.reprojection_ratios
    finally:
        source.close()
    hands = [hand for found in per_frame for hand in found]
    assert sum(bool(found) for found in per_frame) >= 24, 'MediaPipe finds 25-26 of 30'
    assert all(len({hand.side for hand in found}) == len(found) for found in per_frame)
    assert np.mean(np.array(ratios) <= 0.1) >= 0.95, np.round(ratios, 3)
    depths = np.array([hand.joints_cam[WRIST, 2] for hand in hands])
    assert np.all((depths > 0.15) & (depths < 3.0)), depths
    bones = np.stack([_bone_lengths(hand.joints_cam) for hand in hands])
    assert np.max(np.ptp(bones, axis=0) / bones.mean(axis=0)) <= 0.03


def _one_hand_still(stills: list, min_confidence: float = 0.0) -> tuple:
    """Return the first photo where MediaPipe finds one hand (this confident), and that hand."""
    detector = MediaPipeDetector(HandsConfig(source='mediapipe'))
    try:
        for frame in stills:
            detector.reset()
            found = detector.detect(frame.rgb, 0)
            if len(found) == 1 and found[0].confidence > min_confidence:
                return frame, found[0]
    finally:
        detector.close()
    pytest.fail('MediaPipe finds one hand in none of the stills')


@pytest.fixture(scope='module')
def crop_video(stills: list) -> tuple:
    """Return a 16-frame crop video (panning and zooming) around the hand of a one-hand photo."""
    frame, hand = _one_hand_still(stills, min_confidence=0.9)
    centre = hand.joints_2d.mean(axis=0)
    size = np.ptp(hand.joints_2d, axis=0).max()
    phase = np.linspace(0.0, 1.0, 16)
    centres = centre + np.stack([40 * np.sin(2 * np.pi * phase),
                                 25 * np.cos(2 * np.pi * phase)], axis=1)
    widths = np.clip(size * 4 * (1.0 + 0.5 * np.sin(np.pi * phase)), 160, 640)
    frames = crop_stream(frame.rgb, frame.intrinsics, centres, widths)
    return hand.side, frames, _moved(hand.joints_2d, frame.intrinsics, frames)


def _moved(joints_2d: np.ndarray, intrinsics: Intrinsics, frames: list) -> list[np.ndarray]:
    """Return a photo's landmarks in each crop (exact: crops only shift and scale pixels)."""
    centre = np.array([intrinsics.cx, intrinsics.cy])
    return [(joints_2d - centre) * frame.intrinsics.fx / intrinsics.fx
            + [frame.intrinsics.cx, frame.intrinsics.cy] for frame in frames]


def _stream(frames: list, intrinsics: bool = True, **engine_settings: object
            ) -> tuple[list, dict]:
    """Return the results of ``frames`` with MediaPipe hands, and the engine's statistics."""
    config = replace(load_engine_config(), hands=HandsConfig(source='mediapipe'),
                     **engine_settings)
    with StreamingEngine(config) as engine:
        results = []
        for frame in frames:
            results += engine.push(frame.rgb, frame.timestamp_ns,
                                   frame.intrinsics if intrinsics else None)
        return results + engine.flush(), engine.statistics


def _run(frames: list, **engine_settings: object) -> list:
    return _stream(frames, **engine_settings)[0]


@pytest.mark.slow
def test_a_crop_video_keeps_the_hand_in_place_with_one_identity(crop_video: tuple) -> None:
    """Every crop shows the same hand at the same camera-frame place: found, one side, steady.

    Panning and zooming change the hand's pixels by up to 3x; its wrist's camera-frame
    position stays put: sideways within 3 cm, in depth within 10 % of it for the median frame
    and 40 % for every frame (a monocular hand's depth comes from its size in pixels; measured:
    median 6 %, worst 30 % where the hand is about 50 px tall). The output stage keeps one side
    throughout.
    """
    side, frames, _ = crop_video
    results = _run(frames)
    assert all(result.hand_source == 'mediapipe' for result in results)
    found = [result.hands for result in results if result.hands]
    assert len(found) >= 0.9 * len(frames)
    assert {hand.side for hands in found for hand in hands} == {side}
    wrists = np.array([hands[0].joints_cam[WRIST] for hands in found])
    centre = np.median(wrists, axis=0)
    depth_error = np.abs(wrists[:, 2] / centre[2] - 1.0)
    assert np.median(depth_error) <= 0.1 and depth_error.max() <= 0.4, depth_error
    sideways = wrists[:, :2] / wrists[:, 2:] * centre[2]  # lateral position at the median depth
    assert np.abs(sideways - centre[:2]).max() <= 0.03, sideways


def _detected(frames: list, search_interval: int) -> list[list]:
    """Return the MediaPipe detector's hands in each frame of one stream."""
    detector = MediaPipeDetector(HandsConfig(source='mediapipe', scene_cut_distance=1.0,
                                             search_interval=search_interval))
    try:
        return [list(detector.detect(frame.rgb, index)) for index, frame in enumerate(frames)]
    finally:
        detector.close()


def test_one_hand_tracked_alone_finds_what_mediapipe_alone_finds(crop_video: tuple) -> None:
    """The crop video (one hand), twice: found where MediaPipe alone finds it, as accurately.

    Accuracy: the mean landmark distance, over the hand's size, to the photo's landmarks
    moved into each crop. Tracked alone, the hand is never joined by a second one.
    """
    side, frames, truth = crop_video
    frames, truth = frames * 2, truth * 2
    found = {interval: _detected(frames, interval) for interval in (1, 3)}
    assert max(map(len, found[3])) == 1, str(list(map(len, found[3])))
    errors = {interval: np.array([min((np.linalg.norm(hand.joints_2d - joints, axis=1).mean()
                                       / np.ptp(joints, axis=0).max()
                                       for hand in hands if hand.side == side), default=np.inf)
                                  for hands, joints in zip(per_frame, truth)])
              for interval, per_frame in found.items()}
    assert np.mean(np.isfinite(errors[1])) >= 0.9
    assert np.mean(np.isfinite(errors[3][np.isfinite(errors[1])])) >= 0.95
    shared = np.isfinite(errors[1]) & np.isfinite(errors[3])
    assert np.median(errors[3][shared]) <= np.median(errors[1][shared]) + 0.01
    assert np.mean(errors[3][shared]) <= np.mean(errors[1][shared]) + 0.01, (
        errors[3][shared].mean(), errors[1][shared].mean())


def test_a_second_hand_is_found_within_the_search_interval(stills: list) -> None:
    """A real hand still in view; another photo's hand and arm enter at frame 10 and stay."""
    background, first = _one_hand_still(stills)
    patch = hand_and_arm_patch([frame.rgb for frame in stills if frame is not background])
    assert patch is not None
    height, width = background.rgb.shape[:2]
    far_side = 0 if landmark_box(first.joints_2d)[0] > width / 2 else width - patch.shape[1]
    assert patch.shape[1] < width / 2, 'the pasted hand must fit beside the first'
    corners = [(far_side + (-2 if far_side else 2) * (index % 5), height - patch.shape[0])
               for index in range(30)]
    frames = [background] * 10 + pasted_stream(background.rgb, patch, corners,
                                               background.intrinsics)
    interval = 3
    alone, searching = _detected(frames, 1), _detected(frames, interval)
    counts = [len(hands) for hands in alone]
    start = counts.index(2)  # MediaPipe alone finds the second hand on this frame and after
    assert 10 <= start <= 20 and counts == [1] * start + [2] * (40 - start), counts
    counts = [len(hands) for hands in searching]
    later = counts[start + interval:]
    assert counts[:10] == [1] * 10 and later == [2] * len(later), (start, str(counts))
    box, size = landmark_box(first.joints_2d), np.ptp(first.joints_2d, axis=0).max()
    for hands in searching:  # the first hand stays where the photo has it
        same = [hand for hand in hands if box_iou(box, landmark_box(hand.joints_2d)) >= 0.3]
        assert len(same) == 1
        assert np.linalg.norm(same[0].joints_2d - first.joints_2d, axis=1).mean() <= 0.1 * size


@pytest.mark.slow
def test_a_fixed_camera_with_mediapipe_hands_runs_no_geometry_where_intrinsics_are_known(
        crop_video: tuple) -> None:
    """camera_motion static + MediaPipe: the geometry branch only predicts missing intrinsics.

    Given intrinsics: no frame runs it, and the hands are a moving-camera run's (camera
    frame). Without (``lens_warmup: first``): the first ``lens_frames`` frames are predicted
    each on its own, flagged provisional with the median so far, and the median of all of them
    holds for the rest; no frame enters the geometry stream.
    """
    _, frames, _ = crop_video
    moving = _run(frames)
    fixed, statistics = _stream(frames, camera_motion='static')
    assert statistics['frames_without_geometry'] == len(frames)
    assert statistics['frames_with_depth'] == 0
    for one, other in zip(moving, fixed, strict=True):
        assert other.intrinsics == one.intrinsics
        for hand, same in zip(one.hands, other.hands, strict=True):
            np.testing.assert_array_equal(same.joints_cam, hand.joints_cam)
            np.testing.assert_array_equal(same.joints_world, same.joints_cam)
    warmup = 4
    predicted, statistics = _stream(frames, intrinsics=False, camera_motion='static',
                                    lens_frames=warmup, lens_warmup='first')
    assert statistics['frames_without_geometry'] == len(frames)
    assert not statistics['lens_provisional']
    assert [r.provisional_intrinsics for r in predicted] == [True] * (warmup - 1) + [False] * (
        len(frames) - warmup + 1)
    settled = predicted[warmup - 1].intrinsics
    assert settled.fx > 0 and settled.width == frames[0].intrinsics.width
    assert {result.intrinsics for result in predicted[warmup - 1:]} == {settled}


@pytest.mark.slow
def test_unrelated_photos_in_a_row_keep_each_photos_own_hands(stills: list) -> None:
    """Every still is a new scene: the engine gives MediaPipe's sides and hand count per photo.

    Without the cut, hand identity carried a hand's side into the next photo wherever a hand
    of the other side had been (a phantom of the wrong side on the real stills).
    """
    source = _source()
    try:
        expected = [sorted(hand.side for hand in _still_hands(source, frame))
                    for frame in stills]
    finally:
        source.close()
    results = _run(stills, camera_motion='static')
    assert [sorted(hand.side for hand in r.hands) for r in results] == expected


def test_tracking_restarts_at_each_scene_cut_only(stills: list, crop_video: tuple) -> None:
    """Unrelated photos in a row are cuts (MediaPipe restarts); a moving crop video is not."""
    detector = MediaPipeDetector(HandsConfig(source='mediapipe'))
    try:
        cuts = []
        for index, frame in enumerate(stills):
            detector.detect(frame.rgb, index)
            cuts.append(detector.cut)
        assert cuts == [False] + [True] * (len(stills) - 1)
        assert detector.scene_cuts == len(stills) - 1
        detector.reset()
        for index, frame in enumerate(crop_video[1]):
            detector.detect(frame.rgb, index)
        assert detector.scene_cuts == len(stills) - 1 and not detector.cut
    finally:
        detector.close()
    never = MediaPipeDetector(HandsConfig(source='mediapipe', scene_cut_distance=1.0))
    try:
        for index, frame in enumerate(stills[:5]):
            never.detect(frame.rgb, index)
        assert never.scene_cuts == 0
    finally:
        never.close()


@pytest.mark.slow
def test_smoothing_steadies_the_crop_video(crop_video: tuple) -> None:
    """One-Euro smoothing lowers the frame-to-frame jitter of the world wrist on real pixels."""
    _, frames, _ = crop_video
    smoothing = SmoothingConfig(mode='one_euro', min_cutoff_hz=0.5)
    base = load_engine_config()

    def jitter(results: list) -> float:
        wrists = np.array([r.hands[0].joints_world[WRIST] for r in results if r.hands])
        return float(np.linalg.norm(np.diff(wrists, axis=0), axis=1).mean())

    plain = _run(frames, camera_motion='static')
    smooth = _run(frames, camera_motion='static',
                  output=replace(base.output, smoothing=smoothing))
    assert jitter(smooth) < 0.8 * jitter(plain)


@pytest.mark.parametrize('case', ['grayscale', 'tiny', 'huge', 'border', 'blank'])
def test_hard_images_give_finite_hands_or_none(stills: list, case: str) -> None:
    """Grayscale, 24 px, 8K, a hand cut by the border, and no hand: no crash, sane output.

    (MediaPipe itself rarely finds hands in grayscale photos: 1 of the first 10 stills.)
    """
    frame = stills[0]
    image = frame.rgb
    if case == 'grayscale':
        image = np.repeat(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2)
    elif case == 'tiny':
        image = cv2.resize(image, (24, 18), interpolation=cv2.INTER_AREA)
    elif case == 'huge':
        image = cv2.resize(image, (7680, 5760), interpolation=cv2.INTER_LINEAR)
    elif case == 'border':
        x = int(_still_hands(_source(), frame)[0].joints_2d[:, 0].mean())
        image = np.ascontiguousarray(image[:, x:])
    else:
        image = np.full_like(image, 128)
    height, width = image.shape[:2]
    scale = width / frame.rgb.shape[1]
    intrinsics = replace(frame.intrinsics, fx=frame.intrinsics.fx * scale,
                         fy=frame.intrinsics.fy * scale, cx=width / 2, cy=height / 2,
                         width=width, height=height)
    source = _source()
    try:
        hands = source.camera_hands(source.detect(image, 0), (), intrinsics)
    finally:
        source.close()
    assert len({hand.side for hand in hands}) == len(hands) <= 2
    for hand in hands:
        assert np.all(np.isfinite(hand.joints_cam)) and hand.joints_cam[WRIST, 2] > 0
    if case == 'huge':
        assert len(hands) >= 1, 'the hand is still visible in 8K'
    if case == 'blank':
        assert hands == ()


def test_mirrored_images_keep_the_handedness_with_the_flag(stills: list) -> None:
    """A mirrored photo read with hands.mirrored gives the photo's own sides."""
    frame = next(f for f in stills if len(_still_hands(_source(), f)) == 1)
    original = _still_hands(_source(), frame)
    mirrored = replace(frame, rgb=np.ascontiguousarray(frame.rgb[:, ::-1]))
    flagged = _still_hands(_source(mirrored=True), mirrored)
    unflagged = _still_hands(_source(), mirrored)
    assert [hand.side for hand in flagged] == [hand.side for hand in original]
    assert [hand.side for hand in unflagged] == [RIGHT + LEFT - original[0].side]


def test_two_overlapping_hands_give_at_most_one_per_side(stills: list) -> None:
    """A photo blended with its own mirror image: at most one left and one right hand."""
    frame = stills[0]
    blended = (0.5 * frame.rgb + 0.5 * frame.rgb[:, ::-1]).astype(np.uint8)
    hands = _still_hands(_source(), replace(frame, rgb=blended))
    assert len({hand.side for hand in hands}) == len(hands) <= 2


@pytest.mark.slow
def test_a_minute_without_hands_stays_empty_and_bounded() -> None:
    """600 blank frames (1 min at 10 Hz): no hand, no growth of what the source keeps."""
    source = _source(model_complexity=0)
    image = np.full((120, 160, 3), 90, dtype=np.uint8)
    intrinsics = replace(require_stills()[0].intrinsics, fx=125.0, fy=125.0, cx=80.0, cy=60.0,
                         width=160, height=120)
    try:
        for index in range(600):
            assert source.camera_hands(source.detect(image, index), (), intrinsics) == ()
        assert source.statistics()['frames'] == 600 and source.statistics()['hands'] == 0
        assert len(source.reprojection_ratios) == 0
    finally:
        source.close()
