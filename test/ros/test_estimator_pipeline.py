"""The node's per-frame rules around the engine (ros/estimator/pipeline.py), with a stub engine."""

from dataclasses import replace
from types import SimpleNamespace

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.engine.pose_track import TrackedPose
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.ros.estimator.config import CameraSettings
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.pipeline import EstimatorPipeline
import numpy as np
from ros_builders import make_hand
from ros_builders import make_result
from ros_builders import PALM_JOINTS

MS = 1_000_000
POSE = CameraPose(geometry.axis_angle_to_matrix(np.array([0.0, 0.3, 0.0])),
                  np.array([1.0, 2.0, 3.0]))


class StubEngine:
    """Returns queued results from push, records what it was given."""

    def __init__(self, results: list) -> None:
        self.results = list(results)
        self.pushed: list = []
        self.closed = False
        self.model = SimpleNamespace(hand_branch=SimpleNamespace(
            hand_models=[BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT)]))
        self.pose_track = SimpleNamespace(best=self._best)
        self.live_reads: list[bool] = []

    def _best(self, frame_index: int, live: bool = True) -> TrackedPose:
        self.live_reads.append(live)
        if frame_index != 0:
            raise KeyError(frame_index)
        moved = CameraPose(np.eye(3), np.array([9.0, 0.0, 0.0]))
        return TrackedPose(moved, moved, 1.0, 1)

    def push(self, image: np.ndarray, stamp_ns: int, intrinsics: object) -> list:
        self.pushed.append((image.shape, stamp_ns, intrinsics))
        return [self.results.pop(0)]

    def flush(self) -> list:
        return []

    def close(self) -> None:
        self.closed = True


def pipeline(results: list, **overrides: object) -> tuple[EstimatorPipeline, StubEngine]:
    """Return a pipeline over a stub engine (shape sharing off unless overridden)."""
    config = replace(EstimatorConfig(), shape=ShapeConfig(enabled=False), **overrides)
    engine = StubEngine(results)
    return EstimatorPipeline(config, engine), engine


def test_outputs_keep_stamps_identity_and_path() -> None:
    """Stamps pass through, a flipped label is undone, the path refreshes on a new version."""
    first = make_result(0, (make_hand(LEFT, (100, 200), joints_world=PALM_JOINTS),), index=0,
                        pose=POSE)
    flipped = make_result(33 * MS, (make_hand(RIGHT, (102, 200), joints_world=PALM_JOINTS),),
                          index=1, pose=POSE, version=1)
    runner, engine = pipeline([first, flipped])
    image = np.zeros((4, 4, 3), dtype=np.uint8)
    out = runner.process(image, 0, None) + runner.process(image, 33 * MS, None)
    assert [o.stamp_ns for o in out] == [0, 33 * MS]
    assert out[1].hands[RIGHT] is None and out[1].hands[LEFT] is not None
    assert [p.position[0] for _, p in runner.path.poses()] == [9.0, 1.0]
    assert engine.live_reads == [False]  # a refresh leaves the live correction blend alone
    assert engine.pushed[1][1] == 33 * MS
    runner.close()
    assert engine.closed


def test_static_camera_holds_the_pose_and_places_hands_with_it() -> None:
    """camera.motion static: identity pose and world joints equal to camera joints."""
    hand = replace(make_hand(RIGHT), joints_cam=PALM_JOINTS + 0.5,
                   joints_world=POSE.to_world(PALM_JOINTS + 0.5))
    runner, _ = pipeline([make_result(0, (hand,), pose=POSE)],
                         camera=CameraSettings(motion='static'))
    out = runner.process(np.zeros((4, 4, 3), dtype=np.uint8), 0, None)[0]
    np.testing.assert_allclose(out.camera_pose.position, np.zeros(3))
    np.testing.assert_allclose(out.camera_pose.orientation_xyzw, [0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(out.hands[RIGHT].landmarks_world, PALM_JOINTS + 0.5, atol=1e-12)
