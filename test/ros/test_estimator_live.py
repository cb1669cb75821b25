"""The installed estimator live: sample bag replayed in, outputs recorded, clean SIGINT exit.

Separate processes (estimator, record, replay) on a private DDS domain with localhost discovery.
The recorded outputs are checked against the bag's stamps and against the offline engine run
(the node's engine config, output stage included) on exactly the frames the node processed.
"""

import json
from pathlib import Path
import subprocess
import sys
import time

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core.hand_conventions import JOINT_NAMES
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.ros.estimator.config import EngineSelection
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.engine_setup import engine_config_for
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
import torch

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')

OUTPUTS = [f'{NODE}/camera_pose', f'{NODE}/hands/left/landmarks',
           f'{NODE}/hands/right/landmarks', f'{NODE}/hands/right/wrist_frame_landmarks',
           f'{NODE}/hands/joint_names', f'{NODE}/camera_path', f'{NODE}/hands/markers',
           f'{NODE}/camera_info', '/diagnostics']
READY = 'ready: engine'
#: Without BA: its results land at moments an offline run cannot repeat, so poses would differ.
NO_BA = 'none'
#: Live and offline runs do the same float math on the same frames; allow for thread order.
OFFLINE_TOLERANCE = 1e-5
FIXED_INTERVAL = 'geometry_interval=3'
LENS_IN_TURN = 'lens_warmup=first'
#: Run in another process: the reliability of every subscription of each topic in argv.
PROBE = """
import json, sys, time
import rclpy
rclpy.init()
node = rclpy.create_node('qos_probe')
deadline = time.monotonic() + 30.0
while time.monotonic() < deadline and not all(
        node.get_subscriptions_info_by_topic(topic) for topic in sys.argv[1:]):
    time.sleep(0.1)
print(json.dumps({topic: [info.qos_profile.reliability.name for info in
                          node.get_subscriptions_info_by_topic(topic)]
                  for topic in sys.argv[1:]}))
"""


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'estimator').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')


def _subscription_reliability(env: dict[str, str], topics: list[str]) -> dict[str, list[str]]:
    """Return the reliability of every subscription of each topic, seen from another process."""
    done = subprocess.run([sys.executable, '-c', PROBE, *topics], env=env, capture_output=True,
                          text=True, timeout=60, check=True)
    return json.loads(done.stdout)


def _recorded(bag: Path) -> dict[str, list]:
    """Return the recorded messages by topic."""
    by_topic: dict[str, list] = {}
    with BagReader(bag) as reader:
        for topic, _, msg in reader.messages(sorted(reader.topics())):
            by_topic.setdefault(topic, []).append(msg)
    return by_topic


def _model_fov_stamps(recorded_infos: list) -> set[int]:
    """Return the stamps the node ran on the model's field of view, not the bag's CameraInfo.

    CameraInfo comes best-effort: one can be lost or come after the image's wait (the last
    one, as the replay exits), and the node then rightly runs that frame on the model's field
    of view; its ``~/camera_info`` shows which intrinsics each frame used.
    """
    bag_intrinsics = {frame.timestamp_ns: frame.intrinsics
                      for frame in read_camera_frames(SAMPLE_BAG)}
    return {ns_from_stamp(msg.header.stamp) for msg in recorded_infos
            if not np.allclose(np.reshape(msg.k, (3, 3)),
                               bag_intrinsics[ns_from_stamp(msg.header.stamp)].matrix(),
                               rtol=1e-9, atol=0.0)}


def _offline(stamps: list[int], model_fov: set[int], profile: str = 'live',
             settings: str = '') -> list:
    """Run the node's engine (``engine.profile``, ``engine.set``) offline on ``stamps``' frames.

    Frames in ``model_fov`` get no intrinsics (the model's field of view), as they did live.
    On one torch thread, as the node (``ros_env`` sets ``OMP_NUM_THREADS=1``): with another
    thread count the sums round differently, and a mask pixel at the 0.5 threshold can move a
    hand box by a pixel and the hand by centimetres.
    """
    # The node's defaults (config/estimator.yaml is made from them) but BA, as the node ran.
    config = EstimatorConfig(engine=EngineSelection(bundle_adjustment=NO_BA, profile=profile,
                                                    set=settings))
    wanted = set(stamps)
    outputs = []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with StreamingEngine(engine_config_for(config)) as engine:
            for frame in read_camera_frames(SAMPLE_BAG):
                if frame.timestamp_ns in wanted:
                    intrinsics = None if frame.timestamp_ns in model_fov else frame.intrinsics
                    outputs += engine.push(frame.rgb, frame.timestamp_ns, intrinsics)
            outputs += engine.flush()
    finally:
        torch.set_num_threads(threads)
    return outputs


def test_sample_bag_through_the_live_node(tmp_path: Path) -> None:
    """Stamps match inputs, 21-joint arrays, offline-equal results, SIGINT exits 0."""
    env = ros_env(fresh_domain_id())
    lossless = tmp_path / 'lossless_input.yaml'
    lossless.write_text(LOSSLESS_INPUT)
    # A fixed interval: the node's results are compared with an offline run's, and a paced
    # interval follows this machine's timing (engine/pacing.py).
    params = ['--params-file', str(SHARE / 'config' / 'estimator.yaml'),
              '--params-file', str(lossless), '-p', f'engine.bundle_adjustment:={NO_BA}',
              '-p', f"engine.set:='{FIXED_INTERVAL}'"]
    node_log = tmp_path / 'estimator.log'
    with running('estimator', ['--ros-args', *params, *REMAPS], env, node_log) as node, \
            running('record', ['-o', str(tmp_path / 'out'), *OUTPUTS], env,
                    tmp_path / 'record.log') as recorder:
        assert wait_for_text(node_log, READY, node, 120.0), node_log.read_text()
        # The override reaches its topic only; the others keep the sensor-data default.
        assert _subscription_reliability(env, ['/camera/image_raw/compressed',
                                               '/camera/camera_info']) == {
            '/camera/image_raw/compressed': ['RELIABLE'], '/camera/camera_info': ['BEST_EFFORT']}
        replay = start('replay', [str(SAMPLE_BAG), '--rate', '2', '--wait-for-subscribers',
                                  '20', '--delay', '1', '--topics', '/camera/image_raw/compressed',
                                  '/camera/camera_info'], env, tmp_path / 'replay.log')
        assert replay.wait(120) == 0, (tmp_path / 'replay.log').read_text()
        assert wait_for_text(node_log, READY, node, 1.0)
        time.sleep(5.0)  # the last frame's inference and publication
        assert interrupt(node) == 0, node_log.read_text()
        assert interrupt(recorder) == 0, (tmp_path / 'record.log').read_text()
    recorded = _recorded(tmp_path / 'out')
    with BagReader(SAMPLE_BAG) as reader:
        inputs = {ns_from_stamp(m.header.stamp)
                  for _, _, m in reader.messages(['/camera/image_raw/compressed'])}
    poses = recorded[f'{NODE}/camera_pose']
    stamps = [ns_from_stamp(m.header.stamp) for m in poses]
    assert len(stamps) >= 10
    for topic in OUTPUTS[:4] + [f'{NODE}/camera_path', f'{NODE}/camera_info']:
        assert {ns_from_stamp(m.header.stamp) for m in recorded[topic]} <= inputs, topic
    assert {ns_from_stamp(marker.header.stamp) for m in recorded[f'{NODE}/hands/markers']
            for marker in m.markers} <= inputs
    assert stamps == sorted(stamps)
    for topic in OUTPUTS[1:4]:
        assert {len(m.poses) for m in recorded[topic]} <= {0, 21}, topic
    assert recorded[f'{NODE}/hands/joint_names'][0].data.split(',') == list(JOINT_NAMES)
    assert all(m.header.frame_id == 'world' for m in poses)
    values = {v.key: v.value for v in recorded['/diagnostics'][-1].status[0].values}
    assert int(values['frames_received']) == len(inputs)
    assert int(values['frames_published']) == len(stamps)
    assert int(values['frames_received']) == len(stamps) + int(values['frames_dropped'])
    infos = recorded[f'{NODE}/camera_info']
    assert [ns_from_stamp(m.header.stamp) for m in infos] == stamps
    model_fov = _model_fov_stamps(infos)
    assert int(values['intrinsics_from_model']) == len(model_fov)
    assert int(values['intrinsics_from_camera_info']) == len(stamps) - len(model_fov)
    assert int(values['intrinsics_from_fallback']) == 0
    assert len(model_fov) <= len(stamps) // 2, 'most frames must pair with their CameraInfo'
    offline = {out.timestamp_ns: out for out in _offline(stamps, model_fov,
                                                         settings=FIXED_INTERVAL)}
    assert sorted(offline) == stamps
    for msg, stamp in zip(poses, stamps):
        position = msg.pose.position
        np.testing.assert_allclose([position.x, position.y, position.z],
                                   offline[stamp].camera_pose.translation,
                                   atol=OFFLINE_TOLERANCE)
    for msg in recorded[f'{NODE}/hands/right/landmarks']:
        hand = offline[ns_from_stamp(msg.header.stamp)].hand(RIGHT)
        hand = None if hand is None else hand_output(hand)
        assert len(msg.poses) == (0 if hand is None else 21)
        if hand is not None:
            got = np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses])
            np.testing.assert_allclose(got, hand.landmarks_world, atol=OFFLINE_TOLERANCE)


def _landmarks(msg) -> np.ndarray:
    """Return a landmarks message's (N, 3) positions."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses])


def test_a_fixed_camera_reads_hands_on_arrival_and_matches_the_engine_offline(
        tmp_path: Path) -> None:
    """Profile teleop (a fixed camera): hands read from each image's arrival (detect_ahead).

    Replayed at 5 images/s the node processes every frame in order, so its hands equal the
    engine's offline on the same frames; the camera stays the world frame.
    """
    env = ros_env(fresh_domain_id())
    lossless = tmp_path / 'lossless_input.yaml'
    lossless.write_text(LOSSLESS_INPUT)
    # The lens of frames without CameraInfo predicted in turn, not beside the stream (whose
    # provisional lenses follow this machine's timing): the offline run gives the same.
    params = ['--params-file', str(SHARE / 'config' / 'estimator.yaml'),
              '--params-file', str(lossless), '-p', f'engine.bundle_adjustment:={NO_BA}',
              '-p', 'engine.profile:=teleop', '-p', f"engine.set:='{LENS_IN_TURN}'"]
    node_log = tmp_path / 'estimator.log'
    with running('estimator', ['--ros-args', *params, *REMAPS], env, node_log) as node, \
            running('record', ['-o', str(tmp_path / 'out'), *OUTPUTS], env,
                    tmp_path / 'record.log') as recorder:
        assert wait_for_text(node_log, READY, node, 120.0), node_log.read_text()
        replay = start('replay', [str(SAMPLE_BAG), '--rate', '0.5', '--wait-for-subscribers',
                                  '20', '--delay', '1', '--topics', '/camera/image_raw/compressed',
                                  '/camera/camera_info'], env, tmp_path / 'replay.log')
        assert replay.wait(180) == 0, (tmp_path / 'replay.log').read_text()
        time.sleep(3.0)  # the last frame's publication
        assert interrupt(node) == 0, node_log.read_text()
        assert interrupt(recorder) == 0, (tmp_path / 'record.log').read_text()
    recorded = _recorded(tmp_path / 'out')
    poses = recorded[f'{NODE}/camera_pose']
    stamps = [ns_from_stamp(m.header.stamp) for m in poses]
    values = {v.key: v.value for v in recorded['/diagnostics'][-1].status[0].values}
    assert int(values['frames_dropped']) == 0 and len(stamps) == int(values['frames_received'])
    assert len(stamps) == len(list(read_camera_frames(SAMPLE_BAG)))
    for msg in poses:
        pose = msg.pose
        np.testing.assert_allclose([pose.position.x, pose.position.y, pose.position.z,
                                    pose.orientation.x, pose.orientation.y, pose.orientation.z,
                                    pose.orientation.w], [0, 0, 0, 0, 0, 0, 1], atol=1e-12)
    offline = {out.timestamp_ns: out for out in _offline(
        stamps, _model_fov_stamps(recorded[f'{NODE}/camera_info']), profile='teleop',
        settings=LENS_IN_TURN)}
    found = 0
    for side, topic in ((LEFT, f'{NODE}/hands/left/landmarks'),
                        (RIGHT, f'{NODE}/hands/right/landmarks')):
        for msg in recorded[topic]:
            hand = offline[ns_from_stamp(msg.header.stamp)].hand(side)
            assert len(msg.poses) == (0 if hand is None else 21)
            if hand is not None:
                found += 1
                np.testing.assert_allclose(_landmarks(msg), hand_output(hand).landmarks_world,
                                           atol=OFFLINE_TOLERANCE)
    assert found >= len(stamps) // 2
