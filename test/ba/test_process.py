"""BA's own process: arrays out of band, failures reported, crashes replaced, settings stay."""

import multiprocessing
import os
from pathlib import Path
import threading

import cv2
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import WorkerConfig
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.process import BAProcess
from infinihand_ros.ba.process import BAProcessCrashError
from infinihand_ros.ba.process import BAProcessError
from infinihand_ros.ba.process import receive_message
from infinihand_ros.ba.process import send_message
import numpy as np
from process_probes import heavy_modules
import pytest
import torch

#: A niceness that is not the default, so the test sees that it comes from the config.
NICENESS = 7


def _echo(request: object, config: BAConfig, cache: FeatureCache) -> object:
    """Return the request; crash the process for 'crash', raise for 'raise'."""
    if isinstance(request, str) and request == 'crash':
        os._exit(3)
    if isinstance(request, str) and request == 'raise':
        raise ArithmeticError('the BA call went wrong')
    return request


def _settings(request: object, config: BAConfig, cache: FeatureCache) -> dict:
    """Return the child's pid, torch and OpenCV thread counts and each thread's niceness."""
    torch.ones(64, 64) @ torch.ones(64, 64)  # let torch start whatever threads it starts
    return {'pid': os.getpid(), 'torch_threads': torch.get_num_threads(),
            'cv2_threads': cv2.getNumThreads(), 'nice': _nice_values(os.getpid())}


def _nice_values(pid: int) -> list[int]:
    """Return the niceness of every thread of process ``pid`` (Linux /proc)."""
    values = []
    for task in Path(f'/proc/{pid}/task').iterdir():
        fields = (task / 'stat').read_text().rsplit(')', 1)[1].split()
        values.append(int(fields[16]))  # field 19 of stat; the first two were cut off
    return values


def test_messages_carry_arrays_out_of_band() -> None:
    """Arrays arrive equal (and read-only, no copy pickled); None and tuples pass too."""
    sender, receiver = multiprocessing.Pipe()
    image = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    message = {'image': image, 'depth': np.linspace(0.0, 1.0, 6).reshape(2, 3), 'id': 4}
    received = []
    reader = threading.Thread(target=lambda: received.append(receive_message(receiver)))
    reader.start()
    send_message(sender, message)
    reader.join(timeout=10.0)
    out = received[0]
    np.testing.assert_array_equal(out['image'], image)
    np.testing.assert_array_equal(out['depth'], message['depth'])
    assert out['id'] == 4 and not out['image'].flags.writeable


@pytest.mark.skipif(not Path('/proc/self/task').exists(), reason='needs Linux /proc')
def test_settings_stay_in_the_ba_process() -> None:
    """The child runs 1 torch and 1 OpenCV thread, all threads niced; the caller is untouched."""
    torch_threads, cv2_threads = torch.get_num_threads(), cv2.getNumThreads()
    own_nice = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    process = BAProcess(BAConfig(worker=WorkerConfig(niceness=NICENESS)), _settings)
    try:
        child = process.call(None)
    finally:
        process.close()
    assert child['pid'] != os.getpid() and child['torch_threads'] == 1
    assert child['cv2_threads'] == 1 and set(child['nice']) == {NICENESS}
    assert torch.get_num_threads() == torch_threads and cv2.getNumThreads() == cv2_threads
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == own_nice
    assert set(_nice_values(os.getpid())) == {own_nice}  # no thread here was niced


def test_the_ba_process_imports_only_what_ba_needs() -> None:
    """Neither torch nor the caller's main module is imported in the child (fast start)."""
    process = BAProcess(BAConfig(), heavy_modules)
    try:
        assert process.call(None) == []
    finally:
        process.close()


def test_a_failed_call_reports_the_child_traceback_and_the_process_lives_on() -> None:
    """An exception in the child comes back with its traceback; the same child goes on."""
    process = BAProcess(BAConfig(), _echo)
    try:
        with pytest.raises(BAProcessError, match='ArithmeticError: the BA call went wrong') \
                as raised:
            process.call('raise')
        assert 'in _echo' in raised.value.remote_traceback
        pid = process.pid
        assert process.call([1, 2]) == [1, 2] and process.pid == pid and process.starts == 1
    finally:
        process.close()


def test_a_dead_process_is_replaced_on_the_next_call() -> None:
    """A child that dies mid-call fails that call; the next one runs in a new child."""
    process = BAProcess(BAConfig(), _echo)
    try:
        first = process.pid
        with pytest.raises(BAProcessCrashError, match='exit code 3'):
            process.call('crash')
        assert process.call('again') == 'again'
        assert process.starts == 2 and process.pid != first
    finally:
        process.close()
    assert process.pid is None


def test_close_stops_the_child() -> None:
    """After close() the child has exited, also when it never ran a call."""
    for calls in (0, 1):
        process = BAProcess(BAConfig(), _echo)
        pid = process.pid
        for _ in range(calls):
            process.call('x')
        process.close()
        with pytest.raises(ProcessLookupError):  # exited and reaped
            os.kill(pid, 0)
