"""The estimator's ROS interfaces live: ``/tf``, ``~/hands`` and a consumer of both.

The sample bag is replayed into the installed estimator beside the ``retargeting_stub``
(following the right hand) and everything is recorded. ``/tf`` must hold, at each image's
stamp, the camera pose and the wrist poses the standard topics published; ``~/hands`` the same
camera, hands, wrist frames and wrist-frame joints; the stub the wrist-frame landmarks. The
recorded ``~/hands`` and ``/tf`` are then replayed onto the same topics with no estimator
running: the stub reads them as live and answers as before, and ``~/hands`` recorded again
equals the first recording.
"""

from pathlib import Path
import time

from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
from infinihand_ros.tools.node_processes import wait_for_text
from live_processes import LIB
from live_processes import LOSSLESS_INPUT
from live_processes import NODE
from live_processes import REMAPS
from live_processes import running
from live_processes import SAMPLE_BAG
from live_processes import SHARE
from live_processes import start
import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('infinihand_msgs.msg', reason='infinihand_msgs is not built (make)')
pytest.importorskip('tf2_msgs.msg', reason='tf2_msgs is not built (make)')

READY = 'ready: engine'
STUB = '/retargeting_stub'
STUB_READY = 'following the right hand'
HANDS = f'{NODE}/hands'
STUB_OUTPUTS = [f'{STUB}/wrist_pose', f'{STUB}/joints']
OUTPUTS = [HANDS, '/tf', '/tf_static', f'{NODE}/camera_pose', f'{NODE}/camera_info',
           f'{NODE}/hands/left/wrist_pose', f'{NODE}/hands/right/wrist_pose',
           f'{NODE}/hands/right/landmarks', f'{NODE}/hands/right/wrist_frame_landmarks',
           *STUB_OUTPUTS]
STUB_ARGS = ['--ros-args', '-r', f'hands:={HANDS}']
PLAYBACK_S = '5'
EXACT = 1e-12


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'retargeting_stub').exists():
        pytest.skip('the package is not built (make build)')


def _recorded(bag: Path) -> dict[str, list]:
    """Return the recorded messages by topic."""
    by_topic: dict[str, list] = {}
    with BagReader(bag) as reader:
        for topic, _, msg in reader.messages(sorted(reader.topics())):
            by_topic.setdefault(topic, []).append(msg)
    return by_topic


def _by_stamp(messages: list) -> dict[int, object]:
    return {ns_from_stamp(m.header.stamp): m for m in messages}


def _pose(pose) -> list[float]:
    """Return a Pose as [x, y, z, qx, qy, qz, qw]."""
    return [pose.position.x, pose.position.y, pose.position.z, pose.orientation.x,
            pose.orientation.y, pose.orientation.z, pose.orientation.w]


def _transform(transform) -> list[float]:
    """Return a TransformStamped's transform as [x, y, z, qx, qy, qz, qw]."""
    t, q = transform.transform.translation, transform.transform.rotation
    return [t.x, t.y, t.z, q.x, q.y, q.z, q.w]


def _points(points) -> np.ndarray:
    return np.array([[p.x, p.y, p.z] for p in points])


def _landmarks(msg) -> np.ndarray:
    return np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses])


def _run_live(tmp_path: Path, env: dict[str, str]) -> Path:
    """Run the estimator and the stub on the first seconds of the sample bag; return the bag."""
    lossless = tmp_path / 'lossless_input.yaml'
    lossless.write_text(LOSSLESS_INPUT)
    params = ['--params-file', str(SHARE / 'config' / 'estimator.yaml'),
              '--params-file', str(lossless), '-p', 'engine.bundle_adjustment:=none']
    node_log, stub_log = tmp_path / 'estimator.log', tmp_path / 'stub.log'
    out = tmp_path / 'live'
    with running('estimator', ['--ros-args', *params, *REMAPS], env, node_log) as node, \
            running('retargeting_stub', STUB_ARGS, env, stub_log) as stub, \
            running('record', ['-o', str(out), *OUTPUTS], env,
                    tmp_path / 'record.log') as recorder:
        assert wait_for_text(node_log, READY, node, 120.0), node_log.read_text()
        assert wait_for_text(stub_log, STUB_READY, stub, 60.0), stub_log.read_text()
        replay = start('replay', [str(SAMPLE_BAG), '--wait-for-subscribers', '20', '--delay',
                                  '2', '--playback-duration', PLAYBACK_S, '--topics',
                                  '/camera/image_raw/compressed', '/camera/camera_info'],
                       env, tmp_path / 'replay.log')
        assert replay.wait(120) == 0, (tmp_path / 'replay.log').read_text()
        time.sleep(5.0)  # the last frame's inference and publication
        assert interrupt(node) == 0, node_log.read_text()
        assert interrupt(stub) == 0, stub_log.read_text()
        assert interrupt(recorder) == 0, (tmp_path / 'record.log').read_text()
    return out


def _replay_recorded(tmp_path: Path, env: dict[str, str], bag: Path) -> Path:
    """Replay the recorded ``~/hands`` and /tf to the stub alone; return what was recorded."""
    out = tmp_path / 'replayed'
    stub_log = tmp_path / 'stub_replayed.log'
    with running('retargeting_stub', STUB_ARGS, env, stub_log) as stub, \
            running('record', ['-o', str(out), HANDS, *STUB_OUTPUTS], env,
                    tmp_path / 'record_replayed.log') as recorder:
        assert wait_for_text(stub_log, STUB_READY, stub, 60.0), stub_log.read_text()
        # The recorder's subscription alone can satisfy the wait on ~/hands: the delay gives
        # the stub's time to match too (discovery on a loaded machine takes seconds).
        replay = start('replay', [str(bag), '--wait-for-subscribers', '20', '--delay', '6',
                                  '--topics', HANDS, '/tf'], env, tmp_path / 'replay2.log')
        assert replay.wait(120) == 0, (tmp_path / 'replay2.log').read_text()
        time.sleep(4.0)  # the stub answers the last frames
        assert interrupt(stub) == 0, stub_log.read_text()
        assert interrupt(recorder) == 0, (tmp_path / 'record_replayed.log').read_text()
    return out


def test_tf_hands_and_a_consumer_live_and_replayed(tmp_path: Path) -> None:
    """/tf equals the published poses, ~/hands the frame, the stub the wrist-frame landmarks."""
    env = ros_env(fresh_domain_id())
    live = _recorded(_run_live(tmp_path, env))
    poses = _by_stamp(live[f'{NODE}/camera_pose'])
    assert len(poses) >= 10
    camera_frame = live[f'{NODE}/camera_info'][0].header.frame_id
    tf = {}  # (child frame, stamp) -> transform
    for msg in live['/tf']:
        for transform in msg.transforms:
            assert transform.header.frame_id == 'world'
            tf[transform.child_frame_id, ns_from_stamp(transform.header.stamp)] = transform
    assert '/tf_static' not in live  # a moving camera: nothing is fixed
    for stamp, pose in poses.items():
        np.testing.assert_allclose(_transform(tf.pop((camera_frame, stamp))), _pose(pose.pose),
                                   atol=EXACT)
    wrists = 0
    for name in SIDE_NAMES:
        for stamp, pose in _by_stamp(live.get(f'{NODE}/hands/{name}/wrist_pose', [])).items():
            np.testing.assert_allclose(_transform(tf.pop((f'{name}_wrist', stamp))),
                                       _pose(pose.pose), atol=EXACT)
            wrists += 1
    assert wrists >= 3 and not tf, 'every transform is a published pose'

    frames = _by_stamp(live[HANDS])
    assert sorted(frames) == sorted(poses)
    # How each pose was found, and the lens: the sample bag's moving camera is tracked, and its
    # CameraInfo's lens is never provisional.
    tracking = [frame.tracking for frame in frames.values()]
    assert set(tracking) <= {'tracked', 'predicted', 'reinitialised'} and 'tracked' in tracking
    assert not any(frame.intrinsics_provisional for frame in frames.values())
    landmarks = _by_stamp(live[f'{NODE}/hands/right/landmarks'])
    in_wrist = _by_stamp(live[f'{NODE}/hands/right/wrist_frame_landmarks'])
    right_wrists = _by_stamp(live[f'{NODE}/hands/right/wrist_pose'])
    for stamp, frame in frames.items():
        np.testing.assert_allclose(_pose(frame.camera_pose), _pose(poses[stamp].pose),
                                   atol=EXACT)
        right = [hand for hand in frame.hands if hand.side == RIGHT and hand.has_wrist_frame]
        assert len(right) == int(len(landmarks[stamp].poses) == 21)
        if right:
            np.testing.assert_allclose(_points(right[0].joints_world),
                                       _landmarks(landmarks[stamp]), atol=EXACT)
            np.testing.assert_allclose(_points(right[0].joints_wrist),
                                       _landmarks(in_wrist[stamp]), atol=EXACT)
            np.testing.assert_allclose(_pose(right[0].wrist_frame_world),
                                       _pose(right_wrists[stamp].pose), atol=EXACT)

    stub_joints = _by_stamp(live[f'{STUB}/joints'])
    assert len(stub_joints) >= 3
    for stamp, joints in stub_joints.items():
        assert joints.header.frame_id == 'right_wrist'
        np.testing.assert_allclose(_landmarks(joints), _landmarks(in_wrist[stamp]), atol=1e-9)

    replayed = _recorded(_replay_recorded(tmp_path, env, tmp_path / 'live'))
    store = build_typestore()
    assert [bytes(store.serialize_cdr(m, HAND_FRAME_MSG)) for m in replayed[HANDS]] == [
        bytes(store.serialize_cdr(m, HAND_FRAME_MSG)) for m in live[HANDS]]
    again = _by_stamp(replayed[f'{STUB}/joints'])
    assert sorted(again) == sorted(stub_joints)
    for stamp, joints in again.items():
        np.testing.assert_allclose(_landmarks(joints), _landmarks(stub_joints[stamp]),
                                   atol=EXACT)
