"""One live run: the installed estimator (and BA node) fed by ``replay``, watched by ``record``.

Every process is one of the package's installed executables, started on a fresh DDS domain
with localhost-only discovery (``node_processes``). Order: the estimator until its ready line,
the BA node with ``bundle_adjustment: node``, then ``record`` until it has subscribed to every
node output, then ``replay`` of the bag's camera topics (a short delay lets the recorder also
subscribe to the replayed images). After the replay a settle time covers the last inference
and a diagnostics period; then the nodes get SIGINT, the recorder last so it keeps their final
messages. A process that does not start or does not exit 0 raises ``LiveRunError`` naming its log.
"""

import contextlib
from dataclasses import dataclass
from pathlib import Path
import subprocess
import time
from typing import Final

from infinihand_ros.core import topics
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.engine.hands.config import HAND_SOURCES
from infinihand_ros.engine.hands.config import INFINIHAND
from infinihand_ros.eval.recorded import RecordedTopics
from infinihand_ros.ros.estimator.config import BA_MODES
from infinihand_ros.ros.estimator.config import NODE_NAME
from infinihand_ros.tools import node_processes
from infinihand_ros.tools.record import RECORDING

NODE: Final = f'/{NODE_NAME}'
ESTIMATOR_READY: Final = 'ready: engine'
BA_NODE_READY: Final = 'ready:'
#: The bag's camera topics remapped onto the estimator's relative inputs.
REMAPS: Final = ('-r', f'image/compressed:={topics.COMPRESSED_IMAGE_TOPIC}',
                 '-r', f'camera_info:={topics.CAMERA_INFO_TOPIC}')
START_TIMEOUT_S: Final = 300.0
#: Replay waits this long for subscribers, then this much more for the recorder.
SUBSCRIBER_WAIT_S: Final = 30.0
RECORDER_DELAY_S: Final = 1.0
#: After the replay: the last inference and one diagnostics period (1 s by default).
SETTLE_S: Final = 3.0
STOP_TIMEOUT_S: Final = 60.0


class LiveRunError(InfiniHandError):
    """A process of the live run failed to start or to exit cleanly."""


@dataclass(frozen=True)
class LiveRunSpec:
    """What to run.

    Attributes:
        bag: the rosbag2 bag to replay (its compressed images and CameraInfos).
        recorded: bag directory the recorder creates (must not exist).
        logs: directory of the processes' logs (created).
        speed: replay speed (1 real time).
        seconds: replay only the first ``seconds`` of bag time (0: all of it).
        bundle_adjustment: ``none``, ``in_process`` or ``node`` (``engine.bundle_adjustment``).
        hand_source: the node's ``hands.source`` (``infinihand`` for our synthetic bags).

    """

    bag: Path
    recorded: Path
    logs: Path
    speed: float
    seconds: float
    bundle_adjustment: str = 'none'
    hand_source: str = INFINIHAND

    def __post_init__(self) -> None:
        """Check the BA mode (InfiniHandError naming it)."""
        if self.bundle_adjustment not in BA_MODES:
            raise InfiniHandError(f'bundle adjustment: must be one of {list(BA_MODES)}, got '
                                  f'{self.bundle_adjustment!r}')
        if self.hand_source not in HAND_SOURCES:
            raise InfiniHandError(f'hand source: must be one of {list(HAND_SOURCES)}, got '
                                  f'{self.hand_source!r}')


def recorded_topics() -> RecordedTopics:
    """Return the topics the live run records."""
    return RecordedTopics.of_node(NODE)


def _started(stack: contextlib.ExitStack, name: str, args: list[str], env: dict[str, str],
             logs: Path, ready: tuple[str, ...] = ()) -> subprocess.Popen:
    """Start an installed executable; wait until its log holds every line of ``ready``."""
    log = logs / f'{name}.log'
    command = [str(node_processes.package_executable(name)), *args]
    process = stack.enter_context(node_processes.running(command, env, log))
    for text in ready:
        if not node_processes.wait_for_text(log, text, process, START_TIMEOUT_S):
            raise LiveRunError(f'{name} did not get ready (no {text!r} line); see {log}')
    return process


def _stop(process: subprocess.Popen, name: str, logs: Path) -> None:
    """SIGINT ``process``; raise LiveRunError unless it exits 0."""
    code = node_processes.interrupt(process, STOP_TIMEOUT_S)
    if code != 0:
        raise LiveRunError(f'{name} exited {code} on SIGINT; see {logs / (name + ".log")}')


def run_live(spec: LiveRunSpec) -> int:
    """Run the nodes, replay and record (see the module docstring); return the DDS domain id."""
    spec.logs.mkdir(parents=True, exist_ok=True)
    domain_id = node_processes.fresh_domain_id()
    env = node_processes.ros_env(domain_id)
    wanted = recorded_topics()
    params = ['--ros-args', '-p', f"engine.bundle_adjustment:='{spec.bundle_adjustment}'",
              '-p', f"hands.source:='{spec.hand_source}'", *REMAPS]
    with contextlib.ExitStack() as stack:
        estimator = _started(stack, 'estimator', params, env, spec.logs, (ESTIMATOR_READY,))
        nodes = [('estimator', estimator)]
        if spec.bundle_adjustment == 'node':
            nodes.append(('bundle_adjustment', _started(stack, 'bundle_adjustment', [], env,
                                                        spec.logs, (BA_NODE_READY,))))
        subscribed = tuple(f'{RECORDING} {topic} (' for topic in wanted.names()
                           if topic != wanted.image)
        recorder = _started(stack, 'record', ['-o', str(spec.recorded), *wanted.names()], env,
                            spec.logs, subscribed)
        replay = _started(stack, 'replay', [
            str(spec.bag), '--rate', f'{spec.speed:g}', '--playback-duration', f'{spec.seconds:g}',
            '--topics', topics.COMPRESSED_IMAGE_TOPIC, topics.CAMERA_INFO_TOPIC,
            '--wait-for-subscribers', f'{SUBSCRIBER_WAIT_S:g}', '--delay',
            f'{RECORDER_DELAY_S:g}'], env, spec.logs)
        if replay.wait() != 0:
            raise LiveRunError(f'replay exited {replay.returncode}; see {spec.logs}/replay.log')
        time.sleep(SETTLE_S)
        for name, process in nodes:
            _stop(process, name, spec.logs)
        _stop(recorder, 'record', spec.logs)
    return domain_id
