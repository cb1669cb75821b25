"""What the node does with a decoded frame, without ROS: engine, then the output rules.

``EstimatorPipeline.process(rgb, stamp, intrinsics)`` pushes the frame into the streaming
engine and turns each result it returns into a ``FrameOutput``: with ``camera.motion: static``
the camera pose is held at identity (hands placed in the world by the engine's own
``place_in_world``), then hand identity per side, the shared shape per side, smoothing, and the
bounded camera path. With ``engine.bundle_adjustment: node`` each keyframe output also carries
what the bundle-adjustment node needs, and ``apply_corrections`` takes that node's results.
All estimation is the engine's; this only applies the node's rules.
"""

from collections import OrderedDict
from dataclasses import replace

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.engine.output.identity import HandIdentityTracker
from infinihand_ros.engine.output.shape import reshape_hand
from infinihand_ros.engine.output.shape import ShapeConsensus
from infinihand_ros.engine.output.smoothing import HandSmoother
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.engine.world_placement import place_in_world
from infinihand_ros.ros.estimator.camera_path import CameraPath
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.frame_outputs import frame_output
from infinihand_ros.ros.estimator.frame_outputs import FrameOutput
from infinihand_ros.ros.estimator.keyframe_export import apply_corrections
from infinihand_ros.ros.estimator.keyframe_export import keyframe_for_ba
from infinihand_ros.vis.output_fields import PoseFields
import numpy as np

#: Most source images kept for results still to come (more than any engine block holds).
IMAGES_HELD = 64


class EstimatorPipeline:
    """The engine plus the node's per-frame rules (one caller at a time)."""

    def __init__(self, config: EstimatorConfig, engine: StreamingEngine) -> None:
        """Wrap ``engine`` (the pipeline closes it in ``close``)."""
        self.config = config
        self.engine = engine
        self.static = config.camera.motion == 'static'
        self.identity = HandIdentityTracker(config.identity)
        self.shape = ShapeConsensus(config.shape)
        self.smoother = HandSmoother(config.smoothing)
        self.path = CameraPath(config.outputs.path_length)
        self.exports_keyframes = (config.engine.bundle_adjustment == 'node'
                                  and not self.static)
        # Images pushed whose results are not out yet (anchors, windows), by stamp.
        self._images: OrderedDict[int, np.ndarray] = OrderedDict()

    def process(self, rgb: np.ndarray, stamp_ns: int, intrinsics: Intrinsics | None
                ) -> list[FrameOutput]:
        """Push one frame; return the outputs of every result the engine finished.

        Raises:
            InputError: for a frame the engine refuses (the stream is unchanged).
            ModelOutputError: for non-finite network outputs.

        """
        if self.exports_keyframes:
            self._images[stamp_ns] = rgb
            while len(self._images) > IMAGES_HELD:  # frames of a block the model refused
                self._images.popitem(last=False)
        try:
            results = self.engine.push(rgb, stamp_ns, intrinsics)
        except (InputError, ModelOutputError):
            self._images.pop(stamp_ns, None)
            raise
        return [self._output(result) for result in results]

    def apply_corrections(self, times_ns: np.ndarray, corrections: np.ndarray) -> None:
        """Apply bundle-adjustment corrections (K, 4, 4) of keyframes stamped ``times_ns``.

        Call between ``process`` calls (from the thread that calls ``process``); later outputs
        and the refreshed camera path use them.
        """
        apply_corrections(self.engine.pose_track, times_ns, corrections)

    def flush(self) -> list[FrameOutput]:
        """Return the outputs of every frame the engine still holds."""
        return [self._output(result) for result in self.engine.flush()]

    def close(self) -> None:
        """Close the engine."""
        self.engine.close()

    def _output(self, result: FrameResult) -> FrameOutput:
        """Apply the node's rules to one engine result."""
        if self.static:
            identity = CameraPose.identity()
            result = replace(result, camera_pose=identity, raw_camera_pose=None,
                             hands=place_in_world(result.hands, identity))
        size = (result.intrinsics.width, result.intrinsics.height)
        hands = self.identity.assign(result.hands, result.timestamp_ns, size)
        if self.config.shape.enabled:
            hands = tuple(self._shared_shape(hand) for hand in hands)
        hands = self.smoother.apply(hands, result.timestamp_ns)
        output = frame_output(result, hands)
        image = self._images.pop(result.timestamp_ns, None)
        if image is not None:
            output = replace(output, keyframe=keyframe_for_ba(result, image,
                                                              self.engine.pose_track))
        self.path.add(output.frame_index, output.stamp_ns, output.camera_pose,
                      output.pose_version, None if self.static else self._best_pose)
        return output

    def _shared_shape(self, hand: HandState) -> HandState:
        """Feed the shape consensus; give the hand its side's shared shape once there is one."""
        self.shape.observe(hand)
        betas = self.shape.shared(hand.side)
        if betas is None:
            return hand
        return reshape_hand(hand, betas, self.engine.model.hand_branch.hand_models[hand.side])

    def _best_pose(self, frame_index: int) -> PoseFields | None:
        """Return the engine's current best pose of a frame, None once it left the track."""
        try:
            # Not live: a path refresh must not disturb the live frames' correction blend.
            return PoseFields.from_camera_pose(
                self.engine.pose_track.best(frame_index, live=False).camera_pose)
        except KeyError:
            return None
