"""Engine results to the fields of the node's output messages (plain numpy, no ROS types).

Frames (REP 103 / 105): the camera frame is the optical frame (x right, y down, z forward);
``camera_pose`` is ``T_world_cam``, the camera optical frame's pose in the world frame (the
first camera's, or the fixed camera's with ``camera.motion: static``). The per-hand fields are
``vis.output_fields.HandOutput``.
"""

from dataclasses import dataclass

from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.vis.output_fields import hand_output
from infinihand_ros.vis.output_fields import HandOutput
from infinihand_ros.vis.output_fields import PoseFields


@dataclass(frozen=True)
class FrameOutput:
    """Everything the node publishes for one frame.

    Attributes:
        stamp_ns: the source image's stamp (every output header carries it).
        frame_index: 0-based index in the engine's stream.
        camera_pose: ``T_world_cam`` of the optical camera frame.
        intrinsics: the intrinsics the engine used (given or predicted), source pixels.
        hands: per side (index 0 left, 1 right) the hand output, or None when not seen.
        metric_scale: metres per model unit applied to the trajectory.
        pose_version: the engine pose-track version ``camera_pose`` was computed with.
        keyframe: what goes to the bundle-adjustment node for this frame (None: nothing).

    """

    stamp_ns: int
    frame_index: int
    camera_pose: PoseFields
    intrinsics: Intrinsics
    hands: tuple[HandOutput | None, HandOutput | None]
    metric_scale: float
    pose_version: int
    keyframe: KeyframeInput | None = None


def frame_output(result: FrameResult, hands: tuple[HandState, ...] | None = None
                 ) -> FrameOutput:
    """Return the outputs of an engine result.

    Args:
        result: the engine's result for one frame.
        hands: the hands to publish (after identity, shape and smoothing); the result's if None.

    """
    hands = result.hands if hands is None else hands
    by_side = {hand.side: hand_output(hand) for hand in hands}
    return FrameOutput(result.timestamp_ns, result.frame_index,
                       PoseFields.from_camera_pose(result.camera_pose), result.intrinsics,
                       tuple(by_side.get(side) for side in SIDES), result.metric_scale,
                       result.pose_version)
