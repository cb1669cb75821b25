"""rclpy messages of the node's outputs, built from the plain fields of ``core.output_fields``.

Only ROS message classes here, no estimation: every number comes from a ``PoseFields``,
``MarkerSpec``, ``Intrinsics`` or ``DiagnosticReport``. ``joint_names_msg`` is the comma
separated list of the 21 joint names in landmark order.
"""

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import Point
from geometry_msgs.msg import Pose
from geometry_msgs.msg import PoseArray
from geometry_msgs.msg import PoseStamped
from geometry_msgs.msg import Quaternion
from geometry_msgs.msg import Transform
from geometry_msgs.msg import TransformStamped
from geometry_msgs.msg import Vector3
from infinihand_ros.bag.camera_msgs import camera_info_distortion
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.hand_conventions import JOINT_NAMES
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.ros.estimator.diagnostics import DiagnosticReport
from infinihand_ros.vis.markers import LINE_LIST
from infinihand_ros.vis.markers import LINE_STRIP
from infinihand_ros.vis.markers import MarkerSpec
from infinihand_ros.vis.markers import SPHERE_LIST
from nav_msgs.msg import Path
import numpy as np
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import ColorRGBA
from std_msgs.msg import Header
from std_msgs.msg import String
from visualization_msgs.msg import Marker
from visualization_msgs.msg import MarkerArray

JOINT_NAMES_SEPARATOR = ','
_MARKER_TYPES = {LINE_LIST: Marker.LINE_LIST, SPHERE_LIST: Marker.SPHERE_LIST,
                 LINE_STRIP: Marker.LINE_STRIP}


def header(stamp_ns: int, frame_id: str) -> Header:
    """Return a header with the stamp (nanoseconds) and frame id."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


def pose_msg(fields: PoseFields) -> Pose:
    """Return a geometry_msgs/Pose."""
    x, y, z = (float(v) for v in fields.position)
    qx, qy, qz, qw = (float(v) for v in fields.orientation_xyzw)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def pose_stamped_msg(stamp_ns: int, frame_id: str, fields: PoseFields) -> PoseStamped:
    """Return a geometry_msgs/PoseStamped."""
    return PoseStamped(header=header(stamp_ns, frame_id), pose=pose_msg(fields))


def transform_stamped_msg(stamp_ns: int, parent_frame_id: str, child_frame_id: str,
                          fields: PoseFields) -> TransformStamped:
    """Return the TF transform of ``child_frame_id`` in ``parent_frame_id``.

    Args:
        stamp_ns: the stamp, nanoseconds (the source image's).
        parent_frame_id: the frame the pose is given in (header.frame_id).
        child_frame_id: the frame the pose places.
        fields: the child frame's pose in the parent frame (child-to-parent: its position and
            axes in the parent frame).

    """
    x, y, z = (float(v) for v in fields.position)
    qx, qy, qz, qw = (float(v) for v in fields.orientation_xyzw)
    return TransformStamped(header=header(stamp_ns, parent_frame_id),
                            child_frame_id=child_frame_id,
                            transform=Transform(translation=Vector3(x=x, y=y, z=z),
                                                rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))


def pose_array_msg(stamp_ns: int, frame_id: str, points: np.ndarray | None) -> PoseArray:
    """Return a PoseArray of (N, 3) points with identity orientations (empty for None)."""
    poses = [] if points is None else [
        Pose(position=Point(x=float(x), y=float(y), z=float(z))) for x, y, z in points]
    return PoseArray(header=header(stamp_ns, frame_id), poses=poses)


def path_msg(stamp_ns: int, frame_id: str, poses: list[tuple[int, PoseFields]]) -> Path:
    """Return a nav_msgs/Path of (stamp ns, pose) pairs, stamped ``stamp_ns``."""
    return Path(header=header(stamp_ns, frame_id),
                poses=[pose_stamped_msg(stamp, frame_id, pose) for stamp, pose in poses])


def marker_array_msg(stamp_ns: int, frame_id: str, specs: list[MarkerSpec]) -> MarkerArray:
    """Return a MarkerArray of the marker descriptions."""
    markers = []
    for spec in specs:
        marker = Marker(header=header(stamp_ns, frame_id), ns=spec.namespace, id=spec.marker_id,
                        type=_MARKER_TYPES[spec.kind],
                        action=Marker.DELETE if spec.delete else Marker.ADD)
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = marker.scale.z = float(spec.scale_m)
        r, g, b, a = spec.rgba
        marker.color = ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(a))
        marker.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in spec.points]
        markers.append(marker)
    return MarkerArray(markers=markers)


def camera_info_msg(stamp_ns: int, frame_id: str, intrinsics: Intrinsics) -> CameraInfo:
    """Return the CameraInfo of the intrinsics with their lens (pinhole: plumb_bob, zeros)."""
    model, d = camera_info_distortion(intrinsics)
    k = intrinsics.matrix()
    return CameraInfo(header=header(stamp_ns, frame_id), width=intrinsics.width,
                      height=intrinsics.height, distortion_model=model, d=d,
                      k=k.reshape(-1).tolist(),
                      r=np.eye(3).reshape(-1).tolist(),
                      p=np.hstack([k, np.zeros((3, 1))]).reshape(-1).tolist())


def joint_names_msg() -> String:
    """Return the 21 joint names in landmark order, comma separated."""
    return String(data=JOINT_NAMES_SEPARATOR.join(JOINT_NAMES))


def diagnostic_array_msg(stamp_ns: int, name: str, hardware_id: str,
                         report: DiagnosticReport) -> DiagnosticArray:
    """Return a DiagnosticArray holding the report as one status."""
    status = DiagnosticStatus(level=bytes([report.level]), name=name, message=report.message,
                              hardware_id=hardware_id,
                              values=[KeyValue(key=k, value=v) for k, v in report.values])
    return DiagnosticArray(header=header(stamp_ns, ''), status=[status])
