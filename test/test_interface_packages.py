"""The interface packages built from ``msg_schemas/``: infinihand_msgs and, where needed, tf2_msgs.

A TF listener accepts ``/tf`` only when the type hash of our ``tf2_msgs/msg/TFMessage`` is the one
a ROS 2 Jazzy install advertises; the generated ``infinihand_msgs`` types must carry the hashes
and the bytes of the rosbags typestore that writes our bags, so a recorded topic replays.
"""

import json
import os
from pathlib import Path
import subprocess

from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import OUR_MSG_TYPES
import numpy as np
import pytest
from result_builders import make_hand
from result_builders import make_result
from result_builders import PALM_JOINTS

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[1]
#: RIHS01 of tf2_msgs/msg/TFMessage in ROS 2 Jazzy: the hash Jazzy nodes advertise for /tf (as
#: in rmw_zenoh key expressions, ``tf2_msgs::msg::dds_::TFMessage_/RIHS01_e369...``), which
#: rosbags' Jazzy typestore also computes from the upstream definition.
TF_MESSAGE_JAZZY_HASH = 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'


def _generated_hash(typename: str) -> str:
    """Return the RIHS01 hash rosidl generated for ``typename`` in its installed package."""
    packages = pytest.importorskip('ament_index_python.packages')
    package, _, name = typename.split('/')
    try:
        share = Path(packages.get_package_share_directory(package))
    except (packages.PackageNotFoundError, OSError):
        pytest.skip(f'{package} is not built (make build, then source scripts/env.sh)')
    hashes = json.loads((share / 'msg' / f'{name}.json').read_text())['type_hashes']
    return next(item['hash_string'] for item in hashes if item['type_name'] == typename)


def test_tf_message_has_the_ros_jazzy_type_hash() -> None:
    """The TFMessage in use (ours or a ROS install's) hashes as ROS 2 Jazzy's."""
    assert _generated_hash(TF_MESSAGE) == TF_MESSAGE_JAZZY_HASH
    assert build_typestore().hash_rihs01(TF_MESSAGE) == TF_MESSAGE_JAZZY_HASH


@pytest.mark.parametrize('typename', OUR_MSG_TYPES)
def test_generated_types_hash_as_the_bag_typestore(typename: str) -> None:
    """The hash rosidl gives each generated type equals the one our bags are written with."""
    assert _generated_hash(typename) == build_typestore().hash_rihs01(typename)


def test_generated_hand_frame_reads_the_bytes_the_typestore_writes() -> None:
    """A HandFrame serialized by rosbags deserializes in rclpy, and back to the same message.

    Compared after rosbags serializes both (CDR padding bytes from rclpy are not zeroed).
    """
    messages = pytest.importorskip('infinihand_msgs.msg', reason='infinihand_msgs is not built')
    serialization = pytest.importorskip('rclpy.serialization')
    from infinihand_ros.bag.messages import frame_result_to_msg
    store = build_typestore()
    hand = make_hand(1, joints_world=PALM_JOINTS + np.array([0.1, 0.2, 0.3]))
    data = bytes(store.serialize_cdr(
        frame_result_to_msg(store, make_result(1_700_000_000_000_000_005, (hand,)), 'world'),
        HAND_FRAME_MSG))
    msg = serialization.deserialize_message(data, messages.HandFrame)
    assert msg.header.frame_id == 'world' and msg.header.stamp.nanosec == 5
    (got,) = msg.hands
    assert got.side == 1 and got.has_world
    np.testing.assert_array_equal([[p.x, p.y, p.z] for p in got.joints_world],
                                  hand.joints_world)
    back = store.deserialize_cdr(serialization.serialize_message(msg), HAND_FRAME_MSG)
    assert bytes(store.serialize_cdr(back, HAND_FRAME_MSG)) == data


def _selected(prefixes: list[Path]) -> list[str]:
    """Return the interface packages the Makefile builds with ``prefixes`` on the ament path."""
    env = {**os.environ, 'AMENT_PREFIX_PATH': os.pathsep.join(str(p) for p in prefixes)}
    done = subprocess.run([str(ROOT / 'scripts' / 'interface_packages.sh')], env=env,
                          capture_output=True, text=True, check=True)
    return done.stdout.split()


def test_tf2_msgs_is_built_only_where_no_ros_install_has_it(tmp_path: Path) -> None:
    """Our tf2_msgs is built unless a prefix other than this checkout's install provides it."""
    ros = tmp_path / 'opt_ros_jazzy'
    (ros / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    ours = ROOT / 'install' / 'tf2_msgs'
    assert _selected([tmp_path, ours]) == ['msg_schemas', 'msg_schemas/tf2_msgs']
    (ros / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'tf2_msgs').touch()
    assert _selected([ours, ros]) == ['msg_schemas']
