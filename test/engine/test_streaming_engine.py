"""The streaming engine on synthetic frames with the untrained tiny model."""

from dataclasses import replace
import threading
import time

from engine_configs import seeded_tiny
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import PoolConfig
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.config import WorkerConfig
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import rescaled
from infinihand_ros.ba.worker import BARequest
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import EngineStateError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.engine import ba_in_process
from infinihand_ros.engine.ba_in_process import InProcessBA
from infinihand_ros.engine.ba_remote import RemoteBA
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.deferred_geometry import WorkerGate
from infinihand_ros.engine.frame_input import fit_image
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.pose_track import PoseTrackConfig
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
import torch

CONFIG = seeded_tiny(keyframe_interval=2)
NUM_FRAMES = 7


@pytest.fixture(scope='module')
def model():
    """Build the tiny model once (seeded, untrained)."""
    return build_model(CONFIG)


@pytest.fixture(scope='module')
def frames() -> list:
    """Render a short synthetic sequence at 320x240 (letterboxed to the model's 224x168)."""
    return list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5,
                                  num_frames=NUM_FRAMES))


def _run(engine: StreamingEngine, frames: list, with_intrinsics: bool = True) -> list:
    results = []
    for frame in frames:
        results += engine.push(frame.rgb, frame.timestamp_ns,
                               frame.intrinsics if with_intrinsics else None)
    return results + engine.flush()


def test_one_result_per_frame_in_order(model, frames: list) -> None:
    results = _run(StreamingEngine(CONFIG, model), frames)
    assert [r.frame_index for r in results] == list(range(NUM_FRAMES))
    assert [r.timestamp_ns for r in results] == [f.timestamp_ns for f in frames]
    # Two anchors, then every second frame is a keyframe.
    assert [r.is_keyframe for r in results] == [True, True, True, False, True, False, True]
    for result, frame in zip(results, frames):
        assert result.intrinsics == frame.intrinsics
        assert np.all(np.isfinite(result.camera_pose.matrix()))
        assert result.depth is None  # only keyframes sent to BA carry one (or depth_maps)
        for hand in result.hands:
            np.testing.assert_allclose(hand.joints_world,
                                       result.camera_pose.to_world(hand.joints_cam), atol=1e-9)
            assert 0.5 < hand.confidence <= 1.0


def test_the_depth_head_runs_only_where_a_depth_is_used(model, frames: list) -> None:
    """Depth on demand gives the poses and hands of a run with every keyframe's depth map.

    With every frame a scale sample, the depth maps change nothing but the results' depth;
    with the default (a sample every 5th frame once the scale warmed up on the first frame's
    hands) fewer frames run the depth head.
    """
    config = replace(CONFIG, metric_scale=replace(CONFIG.metric_scale, min_samples=1,
                                                  sample_interval=1))
    with StreamingEngine(replace(config, depth_maps=True), model) as engine:
        full = _run(engine, frames)
        full_count = engine.statistics['frames_with_depth']
    with StreamingEngine(config, model) as engine:
        lazy = _run(engine, frames)
    sparse = replace(config, metric_scale=replace(config.metric_scale, sample_interval=5))
    with StreamingEngine(sparse, model) as engine:
        _run(engine, frames)
        sparse_count = engine.statistics['frames_with_depth']
    keyframes = [result.frame_index for result in full if result.is_keyframe]
    assert [r.frame_index for r in full if r.depth is not None] == keyframes
    assert all(result.depth is None for result in lazy)
    assert full_count >= len(keyframes) > sparse_count >= 1  # the tracker's first reference
    for one, other in zip(full, lazy):
        np.testing.assert_array_equal(one.camera_pose.matrix(), other.camera_pose.matrix())
        assert one.metric_scale == other.metric_scale
        for hand, same in zip(one.hands, other.hands, strict=True):
            np.testing.assert_array_equal(hand.joints_world, same.joints_world)


def test_windowed_mode_gives_the_per_frame_results(model, frames: list) -> None:
    per_frame = _run(StreamingEngine(CONFIG, model), frames)
    with StreamingEngine(replace(CONFIG, mode='windowed', window=3), model) as engine:
        windowed = _run(engine, frames)
    assert len(windowed) == len(per_frame)
    for a, b in zip(per_frame, windowed):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-4)
        assert [h.side for h in a.hands] == [h.side for h in b.hands]
        for hand_a, hand_b in zip(a.hands, b.hands):
            np.testing.assert_allclose(hand_a.joints_world, hand_b.joints_world, atol=1e-3)


def test_bad_frames_raise_and_leave_the_stream_intact(model, frames: list) -> None:
    clean = _run(StreamingEngine(CONFIG, model), frames[:4])
    engine = StreamingEngine(CONFIG, model)
    results = []
    for index, frame in enumerate(frames[:4]):
        if index == 2:
            with pytest.raises(InputError, match='expected uint8 pixels'):
                engine.push(frame.rgb.astype(np.float32), frame.timestamp_ns)
            with pytest.raises(InputError, match='image is empty'):
                engine.push(np.zeros((0, 0, 3), np.uint8), frame.timestamp_ns)
            with pytest.raises(InputError, match='intrinsics are for'):
                engine.push(frame.rgb[:100], frame.timestamp_ns, frame.intrinsics)
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    results += engine.flush()
    assert [r.frame_index for r in results] == [0, 1, 2, 3]
    for a, b in zip(clean, results):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_external_corrections_blend_over_the_configured_time(model) -> None:
    """Without in-process BA, outside corrections blend in over ``correction_blend_s``.

    Half of that time after a correction (from the BA node), half of its step is applied.
    """
    config = replace(CONFIG, pose_track=PoseTrackConfig(correction_blend_s=0.4))
    with StreamingEngine(config, model) as engine:
        track = engine.pose_track
        track.add(0, 0, np.eye(4))
        shifted = np.eye(4)
        shifted[0, 3] = 0.1
        track.update_corrections(np.array([0]), shifted[None], np.eye(4)[None])
        track.best(0)  # the live blend starts at the first frame after the correction
        track.add(1, 200_000_000, np.eye(4))
        assert track.best(1).camera_pose.translation[0] == pytest.approx(0.05, abs=1e-6)


def test_reset_starts_a_new_sequence(model, frames: list) -> None:
    engine = StreamingEngine(CONFIG, model)
    first = _run(engine, frames[:3])
    engine.reset()
    second = _run(engine, frames[:3])
    assert [r.frame_index for r in second] == [0, 1, 2]
    for a, b in zip(first, second):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_predicted_field_of_view_without_intrinsics(model, frames: list) -> None:
    results = _run(StreamingEngine(CONFIG, model), frames[:3], with_intrinsics=False)
    for result in results:
        intrinsics = result.intrinsics
        assert (intrinsics.width, intrinsics.height) == (320, 240)
        # The model's principal point is the image centre (W/2, H/2, as Intrinsics.from_fov);
        # letterboxing keeps it there up to the half-pixel of the resampling.
        assert intrinsics.cx == pytest.approx(160.0, abs=0.5)
        assert intrinsics.cy == pytest.approx(120.0, abs=0.5)
        # Untrained FoVs are arbitrary, but clamped to the configured range.
        fov_h, fov_w = np.degrees(intrinsics.fov())
        assert 4.9 < fov_h < 170.1 and 4.9 < fov_w < 170.1


def test_bundle_adjustment_keeps_the_raw_poses(model, frames: list) -> None:
    plain = _run(StreamingEngine(CONFIG, model), frames[:4])
    with StreamingEngine(replace(CONFIG, bundle_adjustment=BAConfig()), model) as engine:
        adjusted = _run(engine, frames[:4])
    for a, b in zip(plain, adjusted):
        assert a.raw_camera_pose is None
        # No BA call yet (the pool has not triggered): the correction is the identity.
        np.testing.assert_allclose(b.raw_camera_pose.matrix(), a.camera_pose.matrix(), atol=1e-6)
        np.testing.assert_allclose(b.camera_pose.matrix(), a.camera_pose.matrix(), atol=1e-6)


def test_static_camera_is_the_world_frame_and_places_hands_with_it(model,
                                                                   frames: list) -> None:
    """camera_motion static: identity pose on every frame, world joints = camera joints."""
    with StreamingEngine(replace(CONFIG, camera_motion='static',
                                 bundle_adjustment=BAConfig()), model) as engine:
        results = _run(engine, frames[:4])
        assert engine.statistics['ba'] is None  # a fixed camera runs no BA
        np.testing.assert_array_equal(engine.best_pose(1).matrix(), np.eye(4))
    for result in results:
        np.testing.assert_array_equal(result.camera_pose.matrix(), np.eye(4))
        assert result.raw_camera_pose is None
        for hand in result.hands:
            np.testing.assert_allclose(hand.joints_world, hand.joints_cam, atol=1e-12)
    with pytest.raises(ConfigError, match='camera_motion'):
        StreamingEngine(replace(CONFIG, camera_motion='static'), model, ba_backend=RemoteBA())


def test_each_result_says_how_its_pose_was_found(model, frames: list) -> None:
    """Each result's ``tracking`` state, as the tracker counted it.

    Tracker on: the first frame is the world (tracked), each later one tracked, predicted or
    reinitialised; off: every pose is the network's (predicted); a fixed camera: static.
    """
    with StreamingEngine(CONFIG, model) as engine:
        tracked = _run(engine, frames[:4])
        counts = engine.statistics['tracker']['states']
    assert tracked[0].tracking == 'tracked'
    assert {r.tracking for r in tracked} <= {'tracked', 'predicted', 'reinitialised'}
    assert counts == {state: sum(r.tracking == state for r in tracked) for state in counts}
    off = replace(CONFIG, tracker=replace(CONFIG.tracker, enabled=False))
    with StreamingEngine(off, model) as engine:
        network = _run(engine, frames[:4])
    assert [r.tracking for r in network] == ['predicted'] * 4
    with StreamingEngine(replace(CONFIG, camera_motion='static'), model) as engine:
        assert {r.tracking for r in _run(engine, frames[:4])} == {'static'}


def test_a_remote_backend_gets_each_keyframe_once_with_its_scaled_pose(model,
                                                                       frames: list) -> None:
    """The engine offers every keyframe (source image, metric depth, scaled raw pose)."""
    remote = RemoteBA()
    with StreamingEngine(CONFIG, model, ba_backend=remote) as engine:
        results = _run(engine, frames)
        offered = remote.take_keyframes()
        poses = {r.frame_index: engine.pose_track.scaled(r.frame_index).matrix()
                 for r in results}
        final_scale = engine.pose_track.scale
    keyframes = [result for result in results if result.is_keyframe]
    assert [k.frame_id for k in offered] == [r.frame_index for r in keyframes]
    for keyframe, result, frame in zip(offered, keyframes, frames):
        np.testing.assert_array_equal(keyframe.image, frames[result.frame_index].rgb)
        np.testing.assert_array_equal(keyframe.depth, result.depth)
        expected = poses[result.frame_index]  # at the final scale; offered at the frame's
        expected[:3, 3] *= result.metric_scale / final_scale
        np.testing.assert_allclose(keyframe.T_world_cam, expected, atol=1e-12)
    assert all(result.raw_camera_pose is not None for result in results)


def test_keyframes_reach_ba_no_closer_than_the_pools_interval(model, frames: list) -> None:
    """A keyframe too soon after the last one offered skips BA, and its depth stays uncomputed."""
    interval = 2.5 * (frames[1].timestamp_ns - frames[0].timestamp_ns)
    ba = BAConfig(pool=PoolConfig(min_interval_s=interval / 1e9))
    remote = RemoteBA()
    with StreamingEngine(replace(CONFIG, bundle_adjustment=ba), model,
                         ba_backend=remote) as engine:
        results = _run(engine, frames)
        offered = [k.frame_id for k in remote.take_keyframes()]
    keyframes = [r.frame_index for r in results if r.is_keyframe]
    assert keyframes == [0, 1, 2, 4, 6]
    assert offered == [0, 4]  # 1 and 2 follow 0 too soon, 6 follows 4 too soon
    assert [r.frame_index for r in results if r.depth is not None] == offered


def test_one_lens_is_held_and_stays_free_for_ba(model, frames: list) -> None:
    """Hands from outside the model, no intrinsics: the first block's lens holds for the stream.

    BA still refines it (its keyframes are not calibrated); given intrinsics are.
    """
    config = replace(CONFIG, hands=replace(CONFIG.hands, source='mediapipe'))
    for given in (False, True):
        remote = RemoteBA()
        with StreamingEngine(config, model, ba_backend=remote) as engine:
            results = _run(engine, frames, with_intrinsics=given)
            offered = remote.take_keyframes()
        assert len({result.intrinsics for result in results}) == 1
        assert offered and all(keyframe.calibrated == given for keyframe in offered)
    with StreamingEngine(replace(config, lens_frames=0), model) as engine:
        assert len({result.intrinsics for result in _run(engine, frames, False)}) > 1


def test_engine_results_equal_a_direct_model_call(model, frames: list) -> None:
    """The engine's camera-space hands and raw poses are the shared forward's, frame by frame.

    The poses are re-anchored to the first frame (``pose_track``): T_0^-1 T_t of the forward's.
    """
    engine_results = _run(StreamingEngine(CONFIG, model), frames[:4])
    stream = model.new_stream()
    direct = []
    with torch.inference_mode():
        for block in ([0, 1], [2], [3]):  # two anchors together, then per frame
            images, mappings = [], []
            for index in block:
                fitted, mapping = fit_image(frames[index].rgb, model.geometry.config.preprocessing,
                                            model.geometry.config.aggregator)
                images.append(torch.from_numpy(fitted).permute(2, 0, 1).float() / 255.0)
                mappings.append(mapping)
            known = torch.ones(1, len(block), dtype=torch.bool)
            intrinsics = torch.as_tensor(np.stack([
                m.intrinsics_to_model(frames[i].intrinsics).matrix()
                for i, m in zip(block, mappings)]))[None]
            flags = [index < 2 or (index - 2) % 2 == 0 for index in block]
            output = model(torch.stack(images)[None], stream, flags, intrinsics, known)
            for row, index in enumerate(block):
                chosen = output.boxes.batch_index == row
                direct.append((output.T_world_cam[0, row].numpy(),
                               output.hands.joints_cam[chosen].numpy(),
                               output.boxes.sides[chosen].tolist()))
    world_from_network = np.linalg.inv(direct[0][0])
    for result, (pose, joints, sides) in zip(engine_results, direct):
        assert result.metric_scale == 1.0  # no scale yet: the raw pose is the result's pose
        np.testing.assert_allclose(result.camera_pose.matrix(), world_from_network @ pose,
                                   atol=1e-6)
        assert [hand.side for hand in result.hands] == sides
        for hand, expected in zip(result.hands, joints):
            np.testing.assert_allclose(hand.joints_cam, expected, atol=1e-6)


@pytest.mark.parametrize('mode', ['per_frame', 'windowed'])
def test_push_after_close_is_refused_without_consuming(model, frames: list, mode: str) -> None:
    """After close() every call raises EngineStateError; close() twice is fine."""
    engine = StreamingEngine(replace(CONFIG, mode=mode, window=2), model)
    engine.push(frames[0].rgb, frames[0].timestamp_ns)
    engine.close()
    engine.close()
    with pytest.raises(EngineStateError, match='after close'):
        engine.push(frames[1].rgb, frames[1].timestamp_ns)
    with pytest.raises(EngineStateError, match='after close'):
        engine.flush()
    assert engine.statistics['frames_pushed'] == 1


def test_a_second_thread_inside_the_engine_is_refused(model, frames: list) -> None:
    """Concurrent calls raise EngineStateError instead of corrupting the stream."""
    engine = StreamingEngine(CONFIG, model)
    inside, release = threading.Event(), threading.Event()
    original = engine.model.run_hands

    def slow_hands(*args, **kwargs):
        inside.set()
        release.wait(10)
        return original(*args, **kwargs)

    engine.model.run_hands = slow_hands
    try:
        worker = threading.Thread(target=_run, args=(engine, frames[:2]))
        worker.start()
        assert inside.wait(30)
        with pytest.raises(EngineStateError, match='two threads at once'):
            engine.push(frames[2].rgb, frames[2].timestamp_ns)
        release.set()
        worker.join(30)
    finally:
        del engine.model.run_hands
    assert engine.statistics['frames_pushed'] == 2


def test_bad_stamps_are_refused_and_leave_the_stream_intact(model, frames: list) -> None:
    """Duplicate, backward and non-integer stamps raise InputError; the stream goes on."""
    engine = StreamingEngine(CONFIG, model)
    results = engine.push(frames[0].rgb, frames[0].timestamp_ns, frames[0].intrinsics)
    for stamp, message in ((frames[0].timestamp_ns, 'duplicate'),
                           (frames[0].timestamp_ns - 1, 'earlier than'),
                           (float('nan'), 'integer nanoseconds'), (None, 'integer')):
        with pytest.raises(InputError, match=message):
            engine.push(frames[1].rgb, stamp, frames[1].intrinsics)
    for frame in frames[1:3]:
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    results += engine.flush()
    clean = _run(StreamingEngine(CONFIG, model), frames[:3])
    assert [r.frame_index for r in results] == [0, 1, 2]
    for a, b in zip(clean, results):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_non_finite_outputs_name_the_weights_and_leave_the_stream(frames: list) -> None:
    """Broken (NaN) weights: ModelOutputError names them; restored, nothing has changed."""
    model = build_model(CONFIG)
    clean = _run(StreamingEngine(CONFIG, model), frames[:4])
    engine = StreamingEngine(CONFIG, model)
    results = []
    for frame in frames[:3]:
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    weight = model.geometry.aggregator.frame_blocks[0].attn.qkv.weight
    saved = weight.detach().clone()
    with torch.no_grad():
        weight.fill_(float('nan'))
    with pytest.raises(ModelOutputError, match='seeded untrained weights .*not finite'):
        engine.push(frames[3].rgb, frames[3].timestamp_ns, frames[3].intrinsics)
    with torch.no_grad():
        weight.copy_(saved)
    results += engine.push(frames[3].rgb, frames[3].timestamp_ns, frames[3].intrinsics)
    results += engine.flush()
    assert [r.frame_index for r in results] == [0, 1, 2, 3]
    for a, b in zip(clean, results):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_windowed_mode_keeps_at_most_one_window_decoding(model, frames: list) -> None:
    """Back-pressure: with a slow hand branch the next window waits, nothing piles up."""
    engine = StreamingEngine(replace(CONFIG, mode='windowed', window=1), model)
    original = engine.model.run_hands

    def slow_hands(*args, **kwargs):
        time.sleep(0.2)
        return original(*args, **kwargs)

    engine.model.run_hands = slow_hands
    try:
        in_flight, results = [], []
        for frame in frames:
            results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
            in_flight.append(engine.statistics['windows_in_flight'])
        results += engine.flush()
    finally:
        del engine.model.run_hands
        engine.close()
    assert max(in_flight) == 1 and len(results) == NUM_FRAMES


def test_flush_during_the_anchors_returns_every_frame(model, frames: list) -> None:
    """Flushing before the anchors are complete still gives a result per pushed frame."""
    engine = StreamingEngine(replace(CONFIG, mode='windowed', window=3), model)
    results = engine.push(frames[0].rgb, frames[0].timestamp_ns) + engine.flush()
    for frame in frames[1:4]:
        results += engine.push(frame.rgb, frame.timestamp_ns)
    results += engine.flush()
    engine.close()
    assert [r.frame_index for r in results] == [0, 1, 2, 3]


def test_a_size_change_mid_stream_is_refused(model, frames: list) -> None:
    """Letterboxing would hide it: the engine refuses frames of another size, stream intact."""
    engine = StreamingEngine(CONFIG, model)
    engine.push(frames[0].rgb, frames[0].timestamp_ns)
    with pytest.raises(InputError, match='320x240 px'):
        engine.push(frames[1].rgb[:200, :300], frames[1].timestamp_ns)
    assert engine.statistics['frames_pushed'] == 1


def test_refined_results_carry_the_final_scale_without_ba(model, frames: list) -> None:
    """Without BA, the final trajectory is the live one at the track's final metric scale."""
    with StreamingEngine(CONFIG, model) as engine:
        live = _run(engine, frames)
        final = engine.refined(live)
        scale = engine.pose_track.scale
    assert len(final) == len(live)
    for before, after in zip(live, final):
        assert after.metric_scale == scale
        np.testing.assert_allclose(after.camera_pose.rotation, before.camera_pose.rotation,
                                   atol=1e-9)
        np.testing.assert_allclose(after.camera_pose.translation,
                                   before.camera_pose.translation * scale / before.metric_scale,
                                   atol=1e-9)
        if before.depth is not None:
            np.testing.assert_allclose(after.depth, before.depth * scale / before.metric_scale,
                                       rtol=1e-6)
        for hand_before, hand_after in zip(before.hands, after.hands):
            np.testing.assert_array_equal(hand_after.joints_cam, hand_before.joints_cam)
            np.testing.assert_allclose(hand_after.joints_world,
                                       after.camera_pose.to_world(hand_after.joints_cam),
                                       atol=1e-9)


def test_refined_results_wait_for_ba_and_apply_every_correction(frames: list) -> None:
    """With BA, refined() waits for the queued calls and gives each frame its corrected pose.

    The pool triggers once over the 7 frames; the refined results carry that call's
    correction in full (no blending). The bundled model boxes the hands (the untrained one's
    boxes can cover the whole image, leaving BA no pixel to track).
    """
    bundled = load_engine_config()
    # The held-out check is off: with 3 keyframes this tests how corrections are applied.
    ba = BAConfig(pool=PoolConfig(trigger=4, stride=2), solver=SolverConfig(holdout_every=0),
                  worker=WorkerConfig(niceness=0, when_behind='wait'))
    config = replace(bundled, keyframe_interval=2, bundle_adjustment=ba)
    with StreamingEngine(config) as engine:
        live = _run(engine, frames)
        final = engine.refined(live)
        statistics = engine.statistics['ba']
        track = engine.pose_track
        stamps = np.array([result.timestamp_ns for result in live])
        corrections = track.corrections.corrections(stamps)
    assert statistics['submitted'] >= 1
    assert statistics['folded_in'] == statistics['done'] == statistics['submitted']
    assert statistics['dropped'] == 0 and statistics['failed'] == 0
    assert not np.allclose(corrections, np.eye(4), atol=1e-9), 'BA changed nothing'
    for before, after, correction in zip(live, final, corrections):
        raw = track.scaled(before.frame_index).matrix()
        np.testing.assert_allclose(after.raw_camera_pose.matrix(), raw, atol=1e-12)
        # Corrections are kept in model units: the metric scale applies after them.
        expected = rescaled(correction @ rescaled(raw, 1.0 / track.scale), track.scale)
        np.testing.assert_allclose(after.camera_pose.matrix(), expected, atol=1e-6)
        for hand in after.hands:
            np.testing.assert_allclose(hand.joints_world,
                                       after.camera_pose.to_world(hand.joints_cam), atol=1e-9)


def _fail_with_frame_0(request: BARequest, config: BAConfig, cache: FeatureCache) -> BAOutput:
    """Raise for a selection holding frame 0 (a solver error), else return its initial poses."""
    keyframes = request.keyframes
    if any(keyframe.frame_id == 0 for keyframe in keyframes):
        raise RuntimeError('solver failed')
    return BAOutput(np.array([k.frame_id for k in keyframes]),
                    np.array([k.timestamp_ns for k in keyframes]),
                    np.stack([k.T_world_cam for k in keyframes]), request.T_world_cam,
                    0, 0, 0, 0.0, 0.0)


class _FailingWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_fail_with_frame_0)


def test_refined_results_flag_the_frames_whose_last_ba_call_failed(
        model, frames: list, monkeypatch: pytest.MonkeyPatch) -> None:
    """refined() flags ``ba_failed`` on exactly the frames the backend reports; live never.

    Keyframes 0, 1, 2, 4, 6 enter a pool (N=2, K=2) that selects [0, 2], [0, 4], [2, 6]: the
    calls holding frame 0 fail and the last one refines frame 2 again, so 0 and 4 are flagged.
    """
    monkeypatch.setattr(ba_in_process, 'BundleAdjustmentWorker', _FailingWorker)
    stage = InProcessBA(BAConfig(pool=PoolConfig(trigger=2, stride=2),
                                 worker=WorkerConfig(when_behind='wait')))
    with StreamingEngine(CONFIG, model, ba_backend=stage) as engine:
        live = _run(engine, frames)
        final = engine.refined(live, timeout_s=60.0)
        statistics = engine.statistics['ba']
        failed = stage.failed_frames()
    assert [result.frame_index for result in live if result.is_keyframe] == [0, 1, 2, 4, 6]
    assert (statistics['done'], statistics['failed']) == (1, 2)
    assert failed == {0, 4}
    assert not any(result.ba_failed for result in live)
    assert [result.frame_index for result in final if result.ba_failed] == [0, 4]


def test_the_hand_depth_correction_multiplies_every_scale_sample(model, frames: list) -> None:
    """The same frames with a correction of 2 give exactly twice the scale estimate."""
    estimates = {}
    for correction in (None, 2.0):
        config = replace(CONFIG, metric_scale=replace(CONFIG.metric_scale, min_samples=1,
                                                      sample_interval=1,
                                                      hand_depth_correction=correction))
        with StreamingEngine(config, model) as engine:
            _run(engine, frames)
            estimates[correction] = engine.pose_track.scale_estimate()
            assert engine.statistics['metric_scale_correction'] == (correction or 1.0)
    assert estimates[None].samples == estimates[2.0].samples > 0
    assert estimates[2.0].scale == pytest.approx(2.0 * estimates[None].scale, rel=1e-9)


def _counting_geometry(engine: StreamingEngine, monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Return a list that gets the frame count of each geometry-branch call of ``engine``."""
    calls: list[int] = []
    run_geometry = engine.model.run_geometry

    def counted(images: torch.Tensor, *args: object, **kwargs: object) -> object:
        calls.append(images.shape[1])
        return run_geometry(images, *args, **kwargs)

    monkeypatch.setattr(engine.model, 'run_geometry', counted)
    return calls


def _interval_config(**settings: object) -> EngineConfig:
    """Return CONFIG with every frame a keyframe, geometry on every 3rd, MediaPipe hands."""
    settings = {'hands': replace(CONFIG.hands, source='mediapipe'), **settings}
    return replace(CONFIG, keyframe_interval=1, geometry_interval=3, **settings)


def test_geometry_runs_on_every_nth_frame_with_hands_from_outside_the_model(
        model, frames: list, monkeypatch: pytest.MonkeyPatch) -> None:
    """geometry_interval 3, MediaPipe hands: the frames between are tracked from the image.

    They carry no depth, enter no memory (every frame that runs the geometry branch is a
    keyframe here) and keep the given intrinsics; the geometry branch runs on the anchors and
    then at most 3 frames apart (sooner where the tracker asks for depth).
    """
    with StreamingEngine(_interval_config(), model) as engine:
        calls = _counting_geometry(engine, monkeypatch)
        results = _run(engine, frames)
        skipped = engine.statistics['frames_without_geometry']
    ran = [r.frame_index for r in results if r.is_keyframe]
    assert [r.frame_index for r in results] == list(range(NUM_FRAMES))
    assert ran[:2] == [0, 1] and sum(calls) == len(ran)
    assert all(b - a <= 3 for a, b in zip(ran, ran[1:])) and ran[-1] >= NUM_FRAMES - 3
    assert skipped == NUM_FRAMES - len(ran) > 0
    for result in results:
        assert np.all(np.isfinite(result.camera_pose.matrix()))
        assert result.intrinsics == frames[result.frame_index].intrinsics
        if not result.is_keyframe:
            assert result.depth is None and result.tracking in ('tracked', 'predicted')


@pytest.mark.parametrize('lag', [0, 1, 2])
def test_results_go_out_before_their_geometry_and_do_not_depend_on_catch_up(
        model, monkeypatch: pytest.MonkeyPatch, lag: int) -> None:
    """A frame due by the interval is answered first; catch_up() (or a later call) runs it.

    Calling catch_up() after every push changes when (and, with ``geometry_lag`` 1 or 2, in
    which thread) the geometry branch runs, not what any result is. (12 frames: the untrained
    model's depth asks for new references often, which run the geometry branch first.)
    """
    frames = list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5, num_frames=12))
    with StreamingEngine(_interval_config(geometry_lag=lag), model) as engine:
        plain = _run(engine, frames)
    with StreamingEngine(_interval_config(geometry_lag=lag), model) as engine:
        threads: list[str] = []
        run_geometry = engine.model.run_geometry

        def counted(*args: object, **kwargs: object) -> object:
            threads.append(threading.current_thread().name)
            return run_geometry(*args, **kwargs)

        monkeypatch.setattr(engine.model, 'run_geometry', counted)
        eager, in_catch_up = [], 0
        for frame in frames:
            eager += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
            before = len(threads)
            engine.catch_up()
            in_catch_up += len(threads) - before
        eager += engine.flush()
    if lag == 0:
        assert in_catch_up > 0
    else:
        assert any(name.startswith('geometry') for name in threads)
    assert len(plain) == len(eager) == len(frames)
    for a, b in zip(plain, eager):
        np.testing.assert_array_equal(a.camera_pose.matrix(), b.camera_pose.matrix())
        assert (a.is_keyframe, a.tracking, len(a.hands)) == (b.is_keyframe, b.tracking,
                                                             len(b.hands))


@pytest.mark.parametrize('settings', [
    {'hands': replace(CONFIG.hands, source='infinihand')}, {'mode': 'windowed', 'window': 4},
    {'tracker': replace(CONFIG.tracker, enabled=False)}, {'camera_motion': 'static'}])
def test_geometry_runs_on_every_frame_where_a_frame_needs_it(
        model, frames: list, monkeypatch: pytest.MonkeyPatch, settings: dict) -> None:
    """The hand branch, windowed mode and an untracked camera need the model on each frame.

    (A fixed camera skips it by its own rule: on given intrinsics, every frame here.)
    """
    with StreamingEngine(_interval_config(**settings), model) as engine:
        calls = _counting_geometry(engine, monkeypatch)
        results = _run(engine, frames)
        skipped = engine.statistics['frames_without_geometry']
    assert len(results) == NUM_FRAMES
    static = settings.get('camera_motion') == 'static'
    assert (sum(calls), skipped) == ((0, NUM_FRAMES) if static else (NUM_FRAMES, 0))


@pytest.mark.parametrize('lag', [0, 1, 2])
def test_a_failed_geometry_after_the_answer_is_counted_and_runs_first_next(
        model, monkeypatch: pytest.MonkeyPatch, lag: int) -> None:
    """Non-finite outputs in the owed geometry: counted, nothing raised; it then runs first.

    catch_up() runs it (``geometry_lag`` 0: counted there) or starts it (n >= 1: counted where
    it is taken in: the (n + 1)-th frame after it, or an earlier one that needs it). The next
    frame then runs the geometry branch first, where a failure raises ``ModelOutputError`` and
    the frame is not consumed; frames keep running it first until it succeeds.
    """
    frames = list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5, num_frames=12))

    def fail(*args: object, **kwargs: object) -> object:
        raise ModelOutputError('non-finite outputs')

    with StreamingEngine(_interval_config(geometry_lag=lag), model) as engine:
        run_geometry = engine.model.run_geometry
        pushed = iter(frames)
        for frame in pushed:
            engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
            if engine._deferred.owed_index is not None:
                break
        owed_index = frame.index
        monkeypatch.setattr(engine.model, 'run_geometry', fail)
        engine.catch_up()  # nothing raised
        assert engine.statistics['geometry_failures'] == (1 if lag == 0 else 0)
        for frame in pushed:
            try:
                engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
            except ModelOutputError:
                break
            assert engine.statistics['geometry_failures'] == 0
        assert 1 <= frame.index - owed_index <= lag + 1
        assert engine.statistics['geometry_failures'] == 1
        assert engine.statistics['frames_pushed'] == frame.index
        monkeypatch.setattr(engine.model, 'run_geometry', run_geometry)
        calls = _counting_geometry(engine, monkeypatch)
        results = engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
        assert calls == [1] and [r.frame_index for r in results] == [frame.index]
        assert engine.statistics['geometry_failures'] == 1


def test_the_geometry_worker_waits_at_block_boundaries_while_a_call_is_inside() -> None:
    """geometry_lag >= 1: the owed geometry stops at the next block while a frame is pushed.

    Only the worker thread waits, and only until the push leaves.
    """
    gate = WorkerGate()
    started, passed = threading.Event(), threading.Event()

    def worker() -> None:
        gate.worker = threading.get_ident()
        started.set()
        gate.boundary()
        passed.set()

    with gate.closed():
        gate.boundary()  # not the worker: no wait
        thread = threading.Thread(target=worker)
        thread.start()
        assert started.wait(5)
        assert not passed.wait(0.2)
    assert passed.wait(5)
    thread.join(5)


def _fixed_camera_config() -> EngineConfig:
    """Return CONFIG for a fixed camera with MediaPipe hands (the teleop case)."""
    return replace(CONFIG, camera_motion='static',
                   hands=replace(CONFIG.hands, source='mediapipe'))


def test_hands_read_ahead_for_a_fixed_camera_give_the_same_results(model) -> None:
    """detect_ahead as each image arrives (another thread, while the last is pushed): same results.

    Only a fixed camera with MediaPipe hands reads ahead; a moving camera does not.
    """
    frames = list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5, num_frames=12))
    with StreamingEngine(_fixed_camera_config(), model) as engine:
        plain = _run(engine, frames)
    started = []
    with StreamingEngine(_fixed_camera_config(), model) as engine:
        assert engine.detects_ahead
        started.append(engine.detect_ahead(frames[0].rgb, frames[0].timestamp_ns))
        ahead = []
        for frame, following in zip(frames, frames[1:] + [None]):
            arrival = threading.Thread(target=lambda image: started.append(engine.detect_ahead(
                image.rgb, image.timestamp_ns)), args=(following,)) if following else None
            if arrival is not None:
                arrival.start()
            ahead += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
            if arrival is not None:
                arrival.join()
        ahead += engine.flush()
    assert started == [True] * len(frames)
    assert sum(len(result.hands) for result in plain) > 0
    assert len(plain) == len(ahead) == len(frames)
    for a, b in zip(plain, ahead):
        assert [hand.side for hand in a.hands] == [hand.side for hand in b.hands]
        for hand_a, hand_b in zip(a.hands, b.hands):
            np.testing.assert_array_equal(hand_a.joints_world, hand_b.joints_world)
    with StreamingEngine(_interval_config(), model) as moving:
        assert not moving.detects_ahead
        assert not moving.detect_ahead(frames[0].rgb, frames[0].timestamp_ns)


def test_hands_read_ahead_of_images_never_pushed_are_dropped(model, frames: list,
                                                             monkeypatch) -> None:
    """Images replaced before their push: their reads are cancelled or dropped, never queued.

    Images arriving faster than the source reads (here 5 at once, a read taking 0.2 s) do not
    queue up: the reads of replaced images that had not begun are cancelled.
    """
    with StreamingEngine(_fixed_camera_config(), model) as engine:
        source = engine._hand_source
        detections = []
        detect = source.detect

        def slow(image: np.ndarray, index: int) -> object:
            detections.append(int(image.sum()))
            time.sleep(0.2)
            return detect(image, index)

        monkeypatch.setattr(source, 'detect', slow)
        assert all(engine.detect_ahead(frame.rgb, frame.timestamp_ns) for frame in frames[:5])
        assert not engine.detect_ahead(frames[2].rgb, frames[2].timestamp_ns)  # older
        results = engine.push(frames[4].rgb, frames[4].timestamp_ns, frames[4].intrinsics)
        # At most the first (begun at once) and the pushed image's own, read ahead.
        assert detections[-1] == int(frames[4].rgb.sum()) and len(detections) <= 2
        read = len(detections)
        assert not engine.detect_ahead(frames[4].rgb, frames[4].timestamp_ns)  # pushed already
        results += engine.push(frames[5].rgb, frames[5].timestamp_ns, frames[5].intrinsics)
        results += engine.flush()
        assert len(detections) == read + 1  # frames[5] was not read ahead: read in its push
    assert [result.timestamp_ns for result in results] == [frames[4].timestamp_ns,
                                                           frames[5].timestamp_ns]
