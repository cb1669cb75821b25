"""BA beside the stream: keyframes reach the pool, BA runs in the background, poses improve."""

from dataclasses import dataclass
import os
import time

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import PoolConfig
from infinihand_ros.ba.config import WorkerConfig
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.worker import BARequest
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.geometry import project_points
from infinihand_ros.engine import ba_in_process
from infinihand_ros.engine.ba_backend import keyframe_input
from infinihand_ros.engine.ba_backend import moving_mask
from infinihand_ros.engine.ba_in_process import InProcessBA
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.pose_track import PoseTrackConfig
from infinihand_ros.synth.arms import arm_points
from infinihand_ros.synth.bag_sink import truth_to_hand_state
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

NUM_FRAMES = 60
#: Seconds ``close`` may take with BA busy (``STOP_WAIT_S`` plus stopping the BA process).
CLOSE_BOUND_S = 2.0


def _drifted(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Return poses whose frame-to-frame motions drift in rotation and scale."""
    raw = truth.copy()
    for index in range(1, len(truth)):
        motion = np.linalg.inv(truth[index - 1]) @ truth[index]
        motion[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.004, 3)).as_matrix() @ \
            motion[:3, :3]
        motion[:3, 3] *= 1.03
        raw[index] = raw[index - 1] @ motion
    return raw


def _keyframe(frame, pose: CameraPose) -> KeyframeInput:
    """Return the BA input of a synthetic frame with a given (drifted, scaled) pose."""
    depth = np.where(np.isfinite(frame.depth), frame.depth, 0.0).astype(np.float32)
    hands = tuple(truth_to_hand_state(h) for h in frame.hands if h.visible)
    return keyframe_input(frame.index, frame.timestamp_ns, frame.rgb, depth, pose,
                          frame.intrinsics, hands)


@dataclass(frozen=True)
class _BARun:
    """One sequence of drifted poses streamed through the stage and the pose track."""

    frames: list
    truth: np.ndarray
    raw: np.ndarray
    stage: InProcessBA
    track: PoseTrack


@pytest.fixture(scope='module')
def ba_run() -> _BARun:
    sequence = SyntheticSequence(SynthConfig(), seed=3, num_frames=NUM_FRAMES)
    frames = list(sequence)
    truth = np.stack([f.camera_pose.matrix() for f in frames])
    raw = _drifted(truth, np.random.default_rng(12345))
    config = BAConfig(pool=PoolConfig(trigger=16, stride=2))
    stage = InProcessBA(config)
    track = PoseTrack(PoseTrackConfig(), MetricScaleConfig(), config.corrections.blend_s)
    for frame, pose in zip(frames, raw):
        track.add(frame.index, frame.timestamp_ns, pose)
        stage.fold_in(track)
        stage.offer(_keyframe(frame, track.scaled(frame.index)))
        while stage.ba.worker.pending():  # a stream slower than BA: no selection is dropped
            time.sleep(0.01)
    stage.close()
    stage.fold_in(track)
    return _BARun(frames, truth, raw, stage, track)


@pytest.mark.slow
def test_background_ba_results_reach_the_track_and_blend_in(ba_run: _BARun) -> None:
    """Every BA call is folded into the pose track; live frames blend the newest one in."""
    stage, track, raw, frames = ba_run.stage, ba_run.track, ba_run.raw, ba_run.frames
    assert stage.ba.calls_submitted >= 3 and stage.calls_done == stage.ba.calls_submitted
    assert stage.ba.worker.dropped == 0 and stage.ba.worker.failures == 0
    assert track.version == stage.calls_done
    # Live frames blend the newest correction in over blend_s (0.3 s): 1 s later it is whole.
    late_index, late_stamp = NUM_FRAMES, frames[-1].timestamp_ns + 1_000_000_000
    track.add(late_index, frames[-1].timestamp_ns + 100_000_000, raw[-1])
    track.best(late_index)
    track.add(late_index + 1, late_stamp, raw[-1])
    final = track.best(late_index + 1)
    correction = track.corrections.corrections(np.array([late_stamp]))[0]
    assert not np.allclose(correction, np.eye(4))
    np.testing.assert_allclose(final.camera_pose.matrix(), correction @ raw[-1], atol=1e-9)
    np.testing.assert_allclose(final.scaled_pose.matrix(), raw[-1], atol=1e-12)  # re-anchored


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    'known BA weakness, open: since the synthetic hands move more (gestures, midline '
    "crossings), BA raises this sequence's ATE from 0.008 to 0.021 m (0.024 with the earlier "
    'depth-prior sigma 0.05); over seeds 1-6, with the earlier settings, it improved 2, was '
    'neutral on 2 and worsened 2 (seeds 3, 4), and seed 4 did better without the hand masks'))
def test_background_ba_lowers_the_ate(ba_run: _BARun) -> None:
    """Refined keyframes and the frames between them: >= 25 % lower ATE (the BA issue's bar)."""
    corrected = np.stack([ba_run.track.best(frame.index, live=False).camera_pose.matrix()
                          for frame in ba_run.frames])

    def ate(poses: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((poses[:, :3, 3] - ba_run.truth[:, :3, 3]) ** 2,
                                            -1))))

    assert ate(corrected) < 0.75 * ate(ba_run.raw)


def test_moving_mask_covers_the_hands_and_their_forearms() -> None:
    """Every visible hand pixel, and the bare forearm's axis in view, lie inside the mask.

    The forearm comes from the synthetic person's arm (wrist to elbow), projected; the mask
    knows only the hand's joints and box.
    """
    frame = SyntheticSequence(SynthConfig(width=96, height=72), seed=1, num_frames=1).frame(0)
    hands = tuple(truth_to_hand_state(h) for h in frame.hands if h.visible)
    mask = moving_mask(hands, frame.intrinsics)
    assert mask.shape == (72, 96)
    for truth in frame.hands:
        if truth.visible:
            assert mask[truth.mask].all()
    large = SyntheticSequence(SynthConfig(), seed=1, num_frames=1)
    frame = large.frame(0)
    hands = tuple(truth_to_hand_state(h) for h in frame.hands if h.visible)
    mask = moving_mask(hands, frame.intrinsics)
    cam_from_scene = np.linalg.inv(large.T_scene_cams[0])
    checked = 0
    for track, joints in zip(large.tracks, large.joints_scene):
        if not any(h.side == track.side for h in hands):
            continue
        wrist, _, elbow, _ = arm_points(joints[0][0], large.T_scene_body[0], track.side,
                                        large.arm_style)
        axis = wrist + np.linspace(0.05, 0.6, 12)[:, None] * (elbow - wrist)
        points = axis @ cam_from_scene[:3, :3].T + cam_from_scene[:3, 3]
        pixels = project_points(points[points[:, 2] > 0.05], frame.intrinsics.matrix())
        col, row = np.round(pixels).astype(int).T
        inside = (col >= 0) & (col < mask.shape[1]) & (row >= 0) & (row < mask.shape[0])
        assert mask[row[inside], col[inside]].all()
        checked += int(inside.sum())
    assert checked >= 6


def _sleep(request: object, config: BAConfig, cache: FeatureCache) -> None:
    """Take far longer than any test waits (a BA call still running at close)."""
    time.sleep(120.0)


def _echo(request: BARequest, config: BAConfig, cache: FeatureCache) -> BAOutput:
    """Return the request's initial poses as refined, a little later (a quick BA stand-in)."""
    time.sleep(0.1)
    keyframes = request.keyframes
    return BAOutput(np.array([k.frame_id for k in keyframes]),
                    np.array([k.timestamp_ns for k in keyframes]),
                    np.stack([k.T_world_cam for k in keyframes]), request.T_world_cam,
                    0, 0, 0, 0.1, 0.0)


def _fail_with_frame_0(request: BARequest, config: BAConfig,
                       cache: FeatureCache) -> BAOutput:
    """Raise for a selection holding frame 0 (a solver error), else stand in like ``_echo``."""
    if any(keyframe.frame_id == 0 for keyframe in request.keyframes):
        raise RuntimeError('solver failed')
    return _echo(request, config, cache)


class _SlowWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_sleep)


class _EchoWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_echo)


class _FailingWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_fail_with_frame_0)


def _plain_keyframe(index: int) -> KeyframeInput:
    """Return a small keyframe 0.1 s after the previous one (only the stand-ins read it)."""
    intrinsics = Intrinsics(50.0, 50.0, 32.0, 24.0, 64, 48)
    return KeyframeInput(index, (index + 1) * 100_000_000, np.zeros((48, 64, 3), np.uint8),
                         np.ones((48, 64), np.float32), np.eye(4), intrinsics,
                         np.zeros((48, 64), bool))


def _alive(pid: int) -> bool:
    """Return whether process ``pid`` exists (not yet reaped)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_close_with_ba_busy_returns_at_once_and_leaves_no_process(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A running call and queued ones: close drops the queue, kills the call, within 2 s."""
    monkeypatch.setattr(ba_in_process, 'BundleAdjustmentWorker', _SlowWorker)
    stage = InProcessBA(BAConfig(pool=PoolConfig(trigger=2, stride=2)))
    worker = stage.ba.worker
    deadline = time.monotonic() + 60.0
    while worker.process_id is None and time.monotonic() < deadline:
        time.sleep(0.01)
    pid = worker.process_id
    keyframes = iter(_plain_keyframe(index) for index in range(100))
    for calls in (1, 3):  # one call running, then two queued behind it
        while stage.ba.calls_submitted < calls:
            stage.offer(next(keyframes))
        time.sleep(0.5)  # the first call is on its way to the (sleeping) BA process
    assert pid is not None and worker.pending() == 3
    start = time.monotonic()
    stage.close()
    assert time.monotonic() - start < CLOSE_BOUND_S
    stats = worker.statistics
    assert (stats.state, stats.done, stats.failed, stats.dropped) == ('stopped', 0, 1, 2)
    assert not _alive(pid)


def test_settle_then_close_gets_every_ba_result_and_stops_at_once(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """An offline run (when_behind: wait) settles: every call is folded in; close is quick."""
    monkeypatch.setattr(ba_in_process, 'BundleAdjustmentWorker', _EchoWorker)
    config = BAConfig(pool=PoolConfig(trigger=2, stride=2),
                      worker=WorkerConfig(when_behind='wait'))
    stage = InProcessBA(config)
    track = PoseTrack(PoseTrackConfig(), MetricScaleConfig(), config.corrections.blend_s)
    for index in range(12):
        keyframe = _plain_keyframe(index)
        track.add(index, keyframe.timestamp_ns, keyframe.T_world_cam)
        stage.fold_in(track)
        stage.offer(keyframe)
    assert stage.ba.calls_submitted >= 4
    assert stage.settle(track, timeout_s=60.0)
    assert stage.calls_done == stage.ba.calls_submitted and stage.ba.worker.dropped == 0
    pid = stage.ba.worker.process_id
    start = time.monotonic()
    stage.close()
    assert time.monotonic() - start < CLOSE_BOUND_S
    assert pid is not None and not _alive(pid)


def test_frames_of_failed_calls_are_reported_until_a_later_call_refines_them(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Calls that raise leave their frames in ``failed_frames``; a later refinement clears one.

    The pool (N=2, K=2) selects frames [0, 2], [0, 3], [2, 4], [3, 5]: the first two calls
    fail, the last two refine frames 2 and 3 again, so only frame 0 stays failed.
    """
    monkeypatch.setattr(ba_in_process, 'BundleAdjustmentWorker', _FailingWorker)
    config = BAConfig(pool=PoolConfig(trigger=2, stride=2),
                      worker=WorkerConfig(when_behind='wait'))
    stage = InProcessBA(config)
    track = PoseTrack(PoseTrackConfig(), MetricScaleConfig(), config.corrections.blend_s)
    try:
        for index in range(6):
            keyframe = _plain_keyframe(index)
            track.add(index, keyframe.timestamp_ns, keyframe.T_world_cam)
            stage.fold_in(track)
            stage.offer(keyframe)
            if index == 3:  # both failing calls are done, no later one has run
                assert stage.settle(track, timeout_s=60.0)
                assert stage.failed_frames() == {0, 2, 3}
        assert stage.settle(track, timeout_s=60.0)
        statistics = stage.statistics()
        assert (statistics['done'], statistics['failed']) == (2, 2)
        assert stage.failed_frames() == {0}
    finally:
        stage.close()
