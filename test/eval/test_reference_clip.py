"""Real head-camera clips against their SfM reference: reading, scoring, and BA on real pixels.

The clips live in ``../shared/data/real_ego`` (never in the repository); the tests skip when it
is absent.
"""

from dataclasses import replace
from pathlib import Path

from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.hand_accounting import account_hands
from infinihand_ros.convert.lerobot_features import frame_values
from infinihand_ros.convert.lerobot_features import HAND_VALID
from infinihand_ros.convert.run import engine_config_for
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.reference_clip import arm_scores
from infinihand_ros.eval.reference_clip import hand_scores
from infinihand_ros.eval.reference_clip import load_reference_clip
from infinihand_ros.eval.reference_clip import mediapipe_hands
from infinihand_ros.eval.reference_clip import mediapipe_labelled
from infinihand_ros.eval.reference_clip import reference_scores
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

REAL_EGO = Path(__file__).resolve().parents[3] / 'shared' / 'data' / 'real_ego'


def _clip(name: str):
    folder = REAL_EGO / name
    if not (folder / 'sfm_poses.json').is_file():
        pytest.skip(f'real clip not found at {folder} (shared data absent)')
    return load_reference_clip(folder)


def test_a_clip_reads_in_time_order_and_scores_zero_against_itself() -> None:
    """Frames, stamps and poses line up; the reference scores 0 against itself, a turn not."""
    clip = _clip('ego4d_counter')
    assert len(clip.files) == len(clip.T_world_cam) == 50
    assert np.all(np.diff(clip.timestamps_ns) > 0)
    image, stamp = next(clip.frames())
    assert image.shape == (288, 384, 3) and stamp == clip.timestamps_ns[0]
    same = reference_scores(clip.T_world_cam, clip)
    assert max(same.values()) < 1e-6
    turned = clip.T_world_cam.copy()
    turned[-1, :3, :3] = Rotation.from_rotvec([0, 0.1, 0]).as_matrix() @ turned[-1, :3, :3]
    assert reference_scores(turned, clip)['end_deg'] == pytest.approx(np.degrees(0.1), rel=1e-6)


def test_a_folder_without_a_reference_is_refused(tmp_path: Path) -> None:
    """A clear error names the folder."""
    with pytest.raises(InputError, match=str(tmp_path)):
        load_reference_clip(tmp_path)


@pytest.mark.slow
def test_the_converters_ba_beats_its_tracker_on_a_real_panning_clip() -> None:
    """ego4d_counter (a 38 deg pan through an uncalibrated lens with k1 = -0.16, per SfM).

    With the converter's settings, the final trajectory (BA) against SfM: ATE at most 3 % of the
    path and 0.8x the tracker's, relative rotation error median at most 0.3 deg, and the
    first-to-last rotation error at most half the tracker's (0.29-0.42 of it in runs so far);
    every BA call passes its held-out check.
    """
    clip = _clip('ego4d_counter')
    with StreamingEngine(engine_config_for(load_convert_config())) as engine:
        live = []
        for image, stamp in clip.frames():
            live += engine.push(image, stamp, None)
        live += engine.flush()
        final = engine.refined(live)
        statistics = engine.statistics['ba']
    tracker = reference_scores(np.stack([r.raw_camera_pose.matrix() for r in final]), clip)
    refined = reference_scores(np.stack([r.camera_pose.matrix() for r in final]), clip)
    assert statistics['done'] >= 1 and statistics['rejected'] == statistics['failed'] == 0
    assert refined['ate_pct'] <= min(3.0, 0.8 * tracker['ate_pct'])
    assert refined['rre_median_deg'] <= 0.3
    assert refined['end_deg'] <= tracker['end_deg'] / 2
    assert not any(result.ba_failed for result in final)


@pytest.mark.slow
def test_a_real_two_handed_clip_through_the_converters_settings() -> None:
    """ego4d_stove (two hands stirring, a near-still head), no intrinsics given.

    One lens for the clip within 10 % of SfM's; the final trajectory within 3 % of the path;
    at least 60 % of MediaPipe alone's hands written on the same side, their world joints
    projected through the written camera a median 0.1 of the hand box or less from
    MediaPipe's landmarks (``benchmarks/real_ego.py`` prints all clips).
    """
    clip = _clip('ego4d_stove')
    with StreamingEngine(engine_config_for(load_convert_config())) as engine:
        live = []
        for image, stamp in clip.frames():
            live += engine.push(image, stamp, None)
        final = engine.refined(live + engine.flush())
    lenses = {result.intrinsics for result in final}
    assert len(lenses) == 1
    assert lenses.pop().fx == pytest.approx(clip.intrinsics.fx, rel=0.1)
    assert reference_scores(np.stack([r.camera_pose.matrix() for r in final]),
                            clip)['ate_pct'] <= 3.0
    hands = hand_scores(final, mediapipe_hands(REAL_EGO / 'ego4d_stove'))
    assert hands['mediapipe_hands'] == 98
    assert hands['found_same_side'] >= 0.6
    assert hands['reprojection_median'] <= 0.1


@pytest.mark.slow
def test_a_followed_hand_takes_mediapipes_majority_side_and_every_hand_is_accounted() -> None:
    """ego4d_counter through the converter's settings (BA off: the hands do not depend on it).

    MediaPipe alone finds 8 "hands" here, all on the blender's white lid at the top of the image
    (the wearer's real hands, at the bottom edge, it never finds): labelled left once, then
    right. Their arm would enter through the top border, so the arm's side of entry decides
    nothing; the hand's history takes the side MediaPipe gives it from its second frame on (7
    of 8 measured; the output stage's identity had kept the first label: 1 of 8). Every hand
    our MediaPipe found is written or dropped for a counted reason.
    """
    folder = REAL_EGO / 'ego4d_counter'
    clip = _clip('ego4d_counter')
    config = replace(engine_config_for(load_convert_config()), bundle_adjustment=None)
    with StreamingEngine(config) as engine:
        before = engine.statistics['hands']
        live = []
        for image, stamp in clip.frames():
            live += engine.push(image, stamp, None)
        final = engine.refined(live + engine.flush())
        after = engine.statistics['hands']
    hands = hand_scores(final, mediapipe_hands(folder))
    assert hands['mediapipe_hands'] == 8
    assert hands['found_same_side'] >= 0.75
    assert arm_scores(final, mediapipe_labelled(folder))['arm_decided'] == 0
    values = [frame_values(result, 0.0) for result in final]
    written = int(sum(columns[HAND_VALID].sum() for columns, _ in values))
    accounting = account_hands(before, after, written, [reasons for _, reasons in values])
    assert accounting.found >= hands['mediapipe_hands'] and accounting.adds_up
