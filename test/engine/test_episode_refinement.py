"""The engine's whole-episode refinement: the written trajectory, its flags and its hands."""

from dataclasses import replace

from engine_configs import seeded_tiny
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import EpisodeConfig
from infinihand_ros.ba.config import WorkerConfig
from infinihand_ros.ba.episode import EpisodeRefinement
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.worker import BARequest
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.engine import ba_in_process
from infinihand_ros.engine.ba_in_process import InProcessBA
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

CONFIG = seeded_tiny(keyframe_interval=2)
BA = BAConfig(worker=WorkerConfig(when_behind='wait'), episode=EpisodeConfig(enabled=True))
#: What the stand-in refinement does to every keyframe but the first: 3 cm along x, 2 deg.
SHIFT = np.eye(4)
SHIFT[:3, :3] = Rotation.from_rotvec([0.0, 0.0, np.radians(2.0)]).as_matrix()
SHIFT[0, 3] = 0.03


@pytest.fixture(scope='module')
def model():
    """Build the tiny model once (seeded, untrained)."""
    return build_model(CONFIG)


@pytest.fixture(scope='module')
def frames() -> list:
    """Render a short synthetic sequence at 320x240 (keyframes 0, 2, 4)."""
    return list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5, num_frames=5))


def _start_poses(request: BARequest, config: BAConfig, cache: FeatureCache) -> BAOutput:
    """Return a streaming call's start poses as its result (no BA: fast)."""
    keyframes = request.keyframes
    return BAOutput(np.array([k.frame_id for k in keyframes]),
                    np.array([k.timestamp_ns for k in keyframes]),
                    np.stack([k.T_world_cam for k in keyframes]), request.T_world_cam,
                    0, 0, 0, 0.0, 0.0)


class _QuickWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_start_poses)


def _run(model, frames: list, accepted: bool, monkeypatch: pytest.MonkeyPatch) -> tuple:
    """Stream the frames with a stand-in refinement; return (final, its calls, statistics)."""
    calls = []

    def refine(keyframes, T_start, lens, config) -> EpisodeRefinement:
        refined = T_start @ SHIFT
        refined[0] = T_start[0]
        calls.append((keyframes, T_start, refined))
        return EpisodeRefinement(accepted, 'stand-in', len(keyframes),
                                 timestamps_ns=np.array([k.timestamp_ns for k in keyframes]),
                                 T_start=T_start, T_refined=refined)

    monkeypatch.setattr(ba_in_process, 'BundleAdjustmentWorker', _QuickWorker)
    monkeypatch.setattr(ba_in_process, 'refine_episode', refine)
    with StreamingEngine(CONFIG, model, ba_backend=InProcessBA(BA)) as engine:
        live = []
        for frame in frames:
            live += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
        live += engine.flush()
        final = engine.refined(live)
        engine.refined(final)  # a second call refines nothing again
        statistics = engine.statistics['ba']
    return final, calls, statistics


def test_an_accepted_refinement_is_written_with_its_hands(model, frames: list,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Keyframes get the refined poses, every frame is flagged, hands follow the written pose."""
    final, calls, statistics = _run(model, frames, True, monkeypatch)
    assert len(calls) == 1 and statistics['episode']['accepted']
    keyframes, _, refined = calls[0]
    by_index = {result.frame_index: result for result in final}
    assert [k.frame_id for k in keyframes] == [r.frame_index for r in final if r.is_keyframe]
    for keyframe, pose in zip(keyframes, refined):
        np.testing.assert_allclose(by_index[keyframe.frame_id].camera_pose.matrix(), pose,
                                   atol=1e-6)
    assert all(result.episode_refined for result in final)
    hands = [(result, hand) for result in final for hand in result.hands]
    assert hands, 'no hand to place'
    for result, hand in hands:
        np.testing.assert_allclose(hand.joints_world, result.camera_pose.to_world(hand.joints_cam),
                                   atol=1e-9)


def test_a_refused_refinement_leaves_the_stream_poses(model, frames: list,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Refused: the keyframes keep the poses it started from, and no frame is flagged."""
    final, calls, statistics = _run(model, frames, False, monkeypatch)
    keyframes, start, _ = calls[0]
    by_index = {result.frame_index: result for result in final}
    for keyframe, pose in zip(keyframes, start):
        np.testing.assert_allclose(by_index[keyframe.frame_id].camera_pose.matrix(), pose,
                                   atol=1e-9)
    assert not any(result.episode_refined for result in final)
    assert statistics['episode']['accepted'] is False
    for result in final:
        for hand in result.hands:
            np.testing.assert_allclose(hand.joints_world,
                                       result.camera_pose.to_world(hand.joints_cam), atol=1e-9)


def test_without_the_setting_no_keyframe_is_kept(model, frames: list) -> None:
    """The live default keeps no keyframes and reports no episode refinement."""
    backend = InProcessBA(replace(BA, episode=EpisodeConfig()))
    with StreamingEngine(CONFIG, model, ba_backend=backend) as engine:
        for frame in frames[:3]:
            engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
        engine.refined(engine.flush())
        assert backend.episode is None and engine.statistics['ba']['episode'] is None
