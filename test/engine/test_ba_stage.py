"""BA beside the stream: keyframes reach the pool, BA runs in the background, corrections land."""

from dataclasses import replace
import time

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import PoolConfig
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.engine.ba_stage import BundleAdjustmentStage
from infinihand_ros.engine.ba_stage import hand_mask_from_boxes
from infinihand_ros.synth.bag_sink import truth_to_hand_state
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

NUM_FRAMES = 60


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


@pytest.mark.slow
def test_background_ba_corrects_drifted_poses(rng: np.random.Generator) -> None:
    sequence = SyntheticSequence(SynthConfig(), seed=3, num_frames=NUM_FRAMES)
    frames = list(sequence)
    truth = np.stack([f.camera_pose.matrix() for f in frames])
    raw = _drifted(truth, rng)
    stage = BundleAdjustmentStage(BAConfig(pool=PoolConfig(trigger=16, stride=2)))
    outputs = []
    for frame, pose in zip(frames, raw):
        depth = np.where(np.isfinite(frame.depth), frame.depth, 0.0).astype(np.float32)
        result = FrameResult(frame.timestamp_ns, frame.index, CameraPose.from_matrix(pose),
                             frame.intrinsics, tuple(truth_to_hand_state(h) for h in frame.hands
                                                     if h.visible),
                             is_keyframe=True, depth=depth)
        outputs.append(stage.apply(result, frame.rgb))
        while stage.worker.pending():  # a stream slower than BA: no selection is dropped
            time.sleep(0.01)
    stage.close()  # let the queued calls finish; the next frames fold them in and blend
    # the newest correction in over corrections.blend_s (0.3 s), so look 1 s later.
    for delay_ns in (100_000_000, 1_000_000_000):
        late = replace(outputs[-1], frame_index=NUM_FRAMES,
                       timestamp_ns=frames[-1].timestamp_ns + delay_ns, is_keyframe=False,
                       camera_pose=CameraPose.from_matrix(raw[-1]), raw_camera_pose=None)
        final = stage.apply(late, frames[-1].rgb)
    assert stage.calls_submitted >= 3 and stage.calls_done == stage.calls_submitted
    assert stage.worker.dropped == 0 and stage.worker.failures == 0
    correction = stage.corrections.corrections(np.array([late.timestamp_ns]))[0]
    assert not np.allclose(correction, np.eye(4))
    np.testing.assert_allclose(final.camera_pose.matrix(), correction @ raw[-1], atol=1e-9)
    # Refined keyframes and the frames between them (the benchmark measures long sequences).
    times = np.array([frame.timestamp_ns for frame in frames])
    corrected = stage.corrections.correct(times, raw)

    def ate(poses: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((poses[:, :3, 3] - truth[:, :3, 3]) ** 2, -1))))

    assert ate(corrected) < 0.75 * ate(raw)  # the issue asks for >= 25 % lower ATE
    np.testing.assert_array_equal(final.raw_camera_pose.matrix(), raw[-1])
    for hand in final.hands:
        np.testing.assert_allclose(hand.joints_world,
                                   final.camera_pose.to_world(hand.joints_cam), atol=1e-9)
        np.testing.assert_allclose(
            hand.mano_world.transl,
            final.camera_pose.rotation @ hand.mano_cam.transl + final.camera_pose.translation,
            atol=1e-9)


def test_hand_mask_covers_the_boxes() -> None:
    frame = SyntheticSequence(SynthConfig(width=96, height=72), seed=1, num_frames=1).frame(0)
    result = FrameResult(frame.timestamp_ns, 0, frame.camera_pose, frame.intrinsics,
                         tuple(truth_to_hand_state(h) for h in frame.hands if h.visible))
    mask = hand_mask_from_boxes(result)
    assert mask.shape == (72, 96)
    for truth in frame.hands:
        if truth.visible:
            assert mask[truth.mask].all()
