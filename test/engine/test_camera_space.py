"""Ground-truth model outputs through the engine's stages: split, pose track, world placement.

A perfect model's outputs (ground-truth poses and depth in units of metres / TRUE_SCALE, masks,
hands) go through ``split_frames``, the pose track and ``place_in_world``: the known metric
scale is recovered and the hands land on the ground truth's world joints.
"""

from types import SimpleNamespace

from infinihand_ros.engine.camera_space import depth_ratios
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.camera_space import split_frames
from infinihand_ros.engine.frame_input import letterbox
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.pose_track import PoseTrackConfig
from infinihand_ros.engine.world_placement import place_in_world
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.infinihand_model import CameraSpaceOutput
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import torch

#: Model units are metres / TRUE_SCALE: the scale the engine must recover.
TRUE_SCALE = 2.5
#: Joints lie inside the hand while depth maps see its skin: a finger's radius nearer, or
#: centimetres nearer where the back of the hand, a curled finger or an arm hides the joint. The
#: median over a hand's joints is biased up by it: about 17 % with hands 0.3-0.5 m away (22 % on
#: this sequence). A lower quantile of the joints lessens the bias on ground truth but made the
#: held-out W-MPJPE worse with the bundled model's depth (87.5 -> 92.0 mm), so the median stays.
SCALE_BIAS_RANGE = (0.97, 1.3)
#: The camera translation then follows the recovered scale.
SCALE_TOLERANCE = 0.3


def _perfect_output(frames: list, mappings: list) -> CameraSpaceOutput:
    """Return what a perfect model would output for ``frames`` (every visible hand detected)."""
    poses = np.stack([frame.camera_pose.matrix() for frame in frames])
    poses[:, :3, 3] /= TRUE_SCALE
    intrinsics = np.stack([m.intrinsics_to_model(f.intrinsics).matrix()
                           for f, m in zip(frames, mappings)])
    depth = np.stack([np.where(np.isfinite(f.depth), f.depth, 100.0) for f in frames])
    masks = np.stack([np.stack([f.hands[0].mask, f.hands[1].mask]) for f in frames])
    geometry = GeometryOutput(
        pose_encoding=torch.zeros(1, len(frames), 9), pose_encoding_iterations=(),
        depth=torch.as_tensor(depth / TRUE_SCALE, dtype=torch.float32)[None],
        depth_conf=torch.ones(1, *depth.shape), hand_masks=torch.as_tensor(masks).float()[None],
        patch_features=torch.zeros(1, len(frames), 4, 3, 4), patch_size=14)
    truths = [(index, side, frame.hands[side]) for index, frame in enumerate(frames)
              for side in (0, 1) if frame.hands[side].visible]

    def stack(values: list) -> torch.Tensor:
        return torch.as_tensor(np.array(values), dtype=torch.float64)

    mano = SimpleNamespace(
        global_orient=stack([t.mano_cam.global_orient for _, _, t in truths]),
        hand_pose=stack([t.mano_cam.hand_pose for _, _, t in truths]),
        betas=stack([t.mano_cam.betas for _, _, t in truths]),
        transl=stack([t.mano_cam.transl for _, _, t in truths]))
    hands = SimpleNamespace(mano_cam=mano, joints_cam=stack([t.joints_cam for _, _, t in truths]),
                            joints_2d=stack([mappings[i].points_to_model(t.joints_2d)
                                             for i, _, t in truths]))
    boxes = HandBoxes(stack([mappings[i].points_to_model(t.box_xyxy.reshape(2, 2)).reshape(4)
                             for i, _, t in truths]).float(),
                      torch.tensor([i for i, _, _ in truths]),
                      torch.tensor([s for _, s, _ in truths]))
    return CameraSpaceOutput(geometry, torch.as_tensor(poses)[None],
                             torch.as_tensor(intrinsics)[None], boxes,
                             torch.ones(len(truths)), hands)


def test_known_scale_and_world_hands_are_recovered() -> None:
    frames = list(SyntheticSequence(SynthConfig(width=224, height=168), seed=6, num_frames=12))
    prepared, mappings = [], []
    for frame in frames:
        pixels, mapping = letterbox(frame.rgb, (224, 168))
        mappings.append(mapping)
        prepared.append(PreparedFrame(frame.index, frame.timestamp_ns,
                                      torch.from_numpy(pixels).permute(2, 0, 1).float() / 255,
                                      mapping, frame.intrinsics, keyframe=True))
    records = split_frames(_perfect_output(frames, mappings), prepared, model=None)
    track = PoseTrack(PoseTrackConfig(), MetricScaleConfig(min_samples=3))
    for record in records:
        track.add(record.frame.index, record.frame.timestamp_ns, record.T_raw)
        ratios = depth_ratios(record.depth.model(), record.frame, record.hands)
        track.observe_scale(ratios, np.ones(len(ratios)))
    low, high = SCALE_BIAS_RANGE
    assert low * TRUE_SCALE <= track.scale <= high * TRUE_SCALE
    truth = frames[-1].camera_pose.translation
    np.testing.assert_allclose(track.best(11).camera_pose.translation,
                               truth * track.scale / TRUE_SCALE, atol=1e-6)
    np.testing.assert_allclose(track.best(11).camera_pose.translation, truth,
                               atol=SCALE_TOLERANCE * np.linalg.norm(truth) + 1e-3)
    detected = 0
    for record, frame in zip(records, frames):
        pose = track.best(record.frame.index).camera_pose
        assert record.intrinsics == frame.intrinsics
        assert record.depth.model().shape == (168, 224)
        for hand in place_in_world(record.hands, pose):
            ground_truth = frame.hands[hand.side]
            np.testing.assert_allclose(hand.joints_world,
                                       pose.to_world(ground_truth.joints_cam), atol=1e-6)
            np.testing.assert_allclose(hand.joints_2d, ground_truth.joints_2d, atol=1e-6)
            np.testing.assert_allclose(hand.mano_world.transl,
                                       pose.rotation @ ground_truth.mano_cam.transl
                                       + pose.translation, atol=1e-6)
            detected += 1
    assert detected >= 12
