"""Decoding with ground-truth geometry: a known metric scale is recovered, hands land in place."""

from types import SimpleNamespace

from infinihand_ros.engine.decode import decode_block
from infinihand_ros.engine.decode import DecodeSettings
from infinihand_ros.engine.decode import PreparedFrame
from infinihand_ros.engine.frame_input import letterbox
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.metric_scale import MetricScaleEstimator
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.pose_encoding import camera_to_encoding
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
import torch

#: Model units are metres / TRUE_SCALE: the scale the engine must recover.
TRUE_SCALE = 2.5
#: Joints lie inside the hand while depth maps see its skin, about a finger's radius nearer:
#: on these sequences that biases the ratio up by 2-6 %.
SCALE_TOLERANCE = 0.08
SETTINGS = DecodeSettings(mask_threshold=0.5, min_pixels=16, presence_threshold=0.5,
                          fov_range_rad=(0.1, 3.0))


class _GroundTruthHands:
    """Stands in for the hand branch: returns each detected hand's ground truth."""

    def __init__(self, frames: list) -> None:
        self.frames = frames

    def __call__(self, images, features, intrinsics, boxes) -> SimpleNamespace:
        truths = [self.frames[int(b)].hands[int(s)] for b, s in
                  zip(boxes.batch_index, boxes.sides)]

        def stack(values: list, shape: tuple) -> torch.Tensor:
            return torch.as_tensor(np.array(values).reshape((len(truths),) + shape))

        mano = SimpleNamespace(
            global_orient=stack([t.mano_cam.global_orient for t in truths], (3,)),
            hand_pose=stack([t.mano_cam.hand_pose for t in truths], (15, 3)),
            betas=stack([t.mano_cam.betas for t in truths], (10,)),
            transl=stack([t.mano_cam.transl for t in truths], (3,)))
        return SimpleNamespace(mano_cam=mano, root_joint=torch.zeros(len(truths), 3),
                               joints_cam=stack([t.joints_cam for t in truths], (21, 3)),
                               joints_2d=stack([t.joints_2d for t in truths], (21, 2)))


def _geometry_output(frames: list) -> GeometryOutput:
    """Build what a perfect geometry branch would output, in units of metres / TRUE_SCALE."""
    encodings = []
    for frame in frames:
        encoding = camera_to_encoding(frame.camera_pose, frame.intrinsics)
        encoding[:3] /= TRUE_SCALE
        encodings.append(encoding)
    depth = np.stack([np.where(np.isfinite(f.depth), f.depth, 100.0) for f in frames])
    masks = np.stack([np.stack([f.hands[0].mask, f.hands[1].mask]) for f in frames])
    encoding = torch.as_tensor(np.array(encodings), dtype=torch.float32)[None]
    return GeometryOutput(
        pose_encoding=encoding, pose_encoding_iterations=(encoding,),
        depth=torch.as_tensor(depth / TRUE_SCALE, dtype=torch.float32)[None],
        depth_conf=torch.ones(1, *depth.shape), hand_masks=torch.as_tensor(masks).float()[None],
        patch_features=torch.zeros(1, len(frames), 4, 3, 4), patch_size=14)


def test_known_scale_and_world_hands_are_recovered() -> None:
    frames = list(SyntheticSequence(SynthConfig(width=224, height=168), seed=6, num_frames=12))
    prepared = []
    for frame in frames:
        pixels, mapping = letterbox(frame.rgb, (224, 168))
        prepared.append(PreparedFrame(frame.index, frame.timestamp_ns,
                                      torch.from_numpy(pixels).permute(2, 0, 1).float() / 255,
                                      mapping, frame.intrinsics, keyframe=True))
    scale = MetricScaleEstimator(MetricScaleConfig(min_samples=3))
    results = decode_block(_geometry_output(frames), prepared, _GroundTruthHands(frames), scale,
                           SETTINGS)
    assert scale.estimate().scale == pytest.approx(TRUE_SCALE, rel=SCALE_TOLERANCE)
    late = results[-1]
    assert late.metric_scale == pytest.approx(TRUE_SCALE, rel=SCALE_TOLERANCE)
    truth = frames[-1].camera_pose.translation
    np.testing.assert_allclose(late.camera_pose.translation, truth,
                               atol=SCALE_TOLERANCE * np.linalg.norm(truth) + 1e-3)
    detected = 0
    for result, frame in zip(results, frames):
        for hand in result.hands:
            truth = frame.hands[hand.side]
            assert truth.visible
            expected = result.camera_pose.to_world(truth.joints_cam)
            np.testing.assert_allclose(hand.joints_world, expected, atol=1e-6)
            np.testing.assert_allclose(hand.mano_world.transl,
                                       result.camera_pose.rotation @ truth.mano_cam.transl
                                       + result.camera_pose.translation, atol=1e-6)
            detected += 1
    assert detected >= 12
