"""Bundle adjustment in its own process, so that it cannot slow down or take down the stream.

A ``BAProcess`` owns one child Python process that runs a BA function (the worker's
``run_request``) with its own ``FeatureCache``. The child is a fresh interpreter started as
``python -m infinihand_ros.ba.process``: it imports only what BA needs (numpy, SciPy, OpenCV;
not torch, not the caller's main module), about 0.5 s of one core, and its settings stay in it:
one BLAS/OpenMP thread, single-threaded OpenCV and the configured niceness for every one of
its threads (it is started from a short-lived thread that lowered its own priority first, so
the child is born with it). The stream's process keeps its torch and OpenCV thread counts and
does not share its interpreter lock with BA.

Requests go through a socket pair as pickle protocol 5 with out-of-band buffers: the images and
depth maps are written straight from the arrays (no pickled copy, the interpreter lock released
while the kernel copies), about 10 ms for an 11-keyframe selection of 518x378 frames. The first
message tells the child its settings and the function to run (a module-level function, imported
by name in the child: ``sys.path`` is passed on).
"""

from collections.abc import Callable
import logging
from multiprocessing.connection import Connection
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import traceback

import cv2
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.core.errors import InfiniHandError

logger = logging.getLogger(__name__)

#: Thread counts of the child's numerical libraries (read when they are imported).
CHILD_THREAD_ENV: dict[str, str] = dict.fromkeys(
    ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'), '1')

#: Seconds a child that ran calls gets to exit on its own when told to stop, before it is
#: killed (one that never ran a call holds nothing and is killed at once).
STOP_TIMEOUT_S = 5.0

#: What the child runs per request: ``run(request, config, cache) -> output``. It must be a
#: module-level function (the child imports it by name).
RunFunction = Callable[[object, BAConfig, FeatureCache], object]


class BAProcessError(InfiniHandError, RuntimeError):
    """A BA call failed in the BA process; ``remote_traceback`` tells where."""

    def __init__(self, message: str, remote_traceback: str = '') -> None:
        """Keep the failure's message and the child's traceback text (if any)."""
        super().__init__(message)
        self.remote_traceback = remote_traceback


class BAProcessCrashError(BAProcessError):
    """The BA process died during a call, or could not be (re)started."""


def send_message(connection: Connection, message: object) -> None:
    """Send ``message`` with its contiguous arrays as out-of-band buffers (no pickled copy)."""
    buffers: list[pickle.PickleBuffer] = []
    header = pickle.dumps(message, protocol=5, buffer_callback=buffers.append)
    connection.send(len(buffers))
    connection.send_bytes(header)
    for buffer in buffers:
        connection.send_bytes(buffer.raw())


def receive_message(connection: Connection) -> object:
    """Receive one ``send_message`` message; its arrays are read-only views of the bytes read.

    Raises:
        EOFError: when the other end closed the pipe.

    """
    count = connection.recv()
    header = connection.recv_bytes()
    return pickle.loads(header, buffers=[connection.recv_bytes() for _ in range(count)])


def serve_requests(connection: Connection) -> None:
    """Child main: read the settings and the BA function, then serve requests until stopped.

    The first message is ``(config, run)``; then messages are ``('call', request)`` or
    ``('stop', None)``; replies are ``('ok', output)`` or ``('error', (message, traceback))``.
    Runs until told to stop or the parent's end closes.
    """
    # Ctrl-C reaches the whole process group: the parent decides when BA stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        config, run = receive_message(connection)
    except EOFError:
        return
    _lower_priority(config.worker.niceness)  # born with it already; this makes sure
    cv2.setNumThreads(1)
    cache = FeatureCache(config.tracking)
    while True:
        try:
            kind, request = receive_message(connection)
        except EOFError:
            return
        if kind != 'call':
            return
        try:
            reply: tuple[str, object] = ('ok', run(request, config, cache))
        except Exception as exc:  # noqa: B902 - every failure goes to the parent, which counts it
            reply = ('error', (f'{type(exc).__name__}: {exc}', traceback.format_exc()))
        send_message(connection, reply)


def _lower_priority(niceness: int) -> None:
    """Set the calling thread's niceness; threads it starts later inherit it (Linux)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), niceness)
    except (AttributeError, OSError) as exc:
        logger.info('BA: could not set niceness %d (%s)', niceness, exc)


def _start_lowered(command: list[str], child_fd: int, niceness: int) -> subprocess.Popen:
    """Start ``command`` from a new thread at ``niceness``: the child inherits the priority."""
    started: list[subprocess.Popen] = []
    failure: list[BaseException] = []
    environment = {**os.environ, **CHILD_THREAD_ENV,
                   'PYTHONPATH': os.pathsep.join(path for path in sys.path if path)}

    def start() -> None:
        _lower_priority(niceness)
        try:
            started.append(subprocess.Popen(command, pass_fds=(child_fd,), env=environment))
        except Exception as exc:  # noqa: B902 - re-raised in the calling thread below
            failure.append(exc)

    starter = threading.Thread(target=start, name='bundle_adjustment_start')
    starter.start()
    starter.join()
    if failure:
        raise BAProcessCrashError(f'BA process could not be started ({failure[0]!r}): is '
                                  f'{sys.executable} still there?') from failure[0]
    return started[0]


class BAProcess:
    """One BA child process: ``call`` runs a request there and returns its output.

    Not thread-safe: one caller (the worker's thread) at a time. A child that dies is replaced
    by a new one on the next call.
    """

    def __init__(self, config: BAConfig, run: RunFunction) -> None:
        """Start the child process (it takes about half a second to import; calls wait).

        Args:
            config: BA settings (the child's niceness, tracking and solver settings).
            run: what the child runs per request (a module-level function).

        Raises:
            BAProcessCrashError: when the child process cannot be started.

        """
        self.config = config
        self._run = run
        self._process: subprocess.Popen | None = None
        self._connection: Connection | None = None
        self._calls = 0  # calls sent to the current child
        self.starts = 0
        self._start()

    @property
    def pid(self) -> int | None:
        """Return the running child's process id, or None."""
        return None if self._process is None else self._process.pid

    def call(self, request: object) -> object:
        """Run ``request`` in the child and return what ``run`` returned for it.

        Raises:
            BAProcessError: when the call failed in the child (with the child's traceback).
            BAProcessCrashError: when the child died or could not be (re)started; the next
                call starts a new child.

        """
        if self._process is None or self._process.poll() is not None:
            self._stop(kill=True)
            self._start()
        self._calls += 1
        try:
            send_message(self._connection, ('call', request))
            status, payload = receive_message(self._connection)
        except (EOFError, OSError) as exc:  # the child died: start a new one next time
            code = self._stop(kill=True)
            raise BAProcessCrashError(f'BA process died during the call (exit code {code}, '
                                      f'{exc!r}); a new one starts with the next call') from exc
        if status != 'ok':
            message, remote_traceback = payload
            raise BAProcessError(message, remote_traceback)
        return payload

    def close(self) -> None:
        """Tell the child to exit and wait for it (killed after ``STOP_TIMEOUT_S``)."""
        self._stop(kill=False)

    def kill(self) -> None:
        """Kill the child at once (a call waiting on it then fails, a polite stop ends).

        Safe from any thread.
        """
        process = self._process
        if process is None:
            return
        try:
            process.kill()
        except OSError as exc:  # reaped meanwhile by the calling thread: nothing to kill
            logger.debug('BA process already gone (%s)', exc)

    def _start(self) -> None:
        """Start a child with its end of a new socket pair and send it its settings."""
        parent_end, child_end = socket.socketpair()
        connection = Connection(parent_end.detach())
        try:
            process = _start_lowered(
                [sys.executable, '-m', 'infinihand_ros.ba.process', str(child_end.fileno())],
                child_end.fileno(), self.config.worker.niceness)
        except BAProcessCrashError:
            connection.close()
            raise
        finally:
            child_end.close()  # the child holds its own copy; ours would hide its exit
        try:
            send_message(connection, (self.config, self._run))
        except OSError as exc:  # died at once: the first call starts another
            logger.warning('BA process gone before it got its settings (%s)', exc)
        self._process, self._connection, self._calls = process, connection, 0
        self.starts += 1

    def _stop(self, kill: bool) -> int | None:
        """Stop the child (politely unless ``kill``), close the socket; return its exit code."""
        process, connection, calls = self._process, self._connection, self._calls
        if process is None:
            return None
        if not kill and calls and process.poll() is None:
            try:
                send_message(connection, ('stop', None))
            except OSError as exc:
                logger.debug('BA process gone before it was told to stop (%s)', exc)
            try:
                process.wait(STOP_TIMEOUT_S)  # still reachable by ``kill`` meanwhile
            except subprocess.TimeoutExpired:
                logger.warning('BA process did not stop within %.0f s: killed', STOP_TIMEOUT_S)
        self._process = self._connection = None
        if process.poll() is None:
            process.kill()
        code = process.wait()
        connection.close()
        return code


if __name__ == '__main__':
    serve_requests(Connection(int(sys.argv[1])))
