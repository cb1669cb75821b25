"""Node start-up and shutdown (ros/node_process.py): SIGINT mid-spin is a clean exit."""

import gc

from infinihand_ros.ros import node_process
import pytest
import rclpy


class _Node:
    """A stand-in node that records whether it was closed."""

    closed = False

    def close(self) -> None:
        self.closed = True

    def destroy_node(self) -> None:
        pass


class _Executor:
    """A stand-in executor whose spin ends with ``error`` after shutting rclpy down or not."""

    def __init__(self, error: BaseException, shut_down: bool) -> None:
        self.error, self.shut_down = error, shut_down

    def add_node(self, node: _Node) -> None:
        pass

    def spin(self) -> None:
        if self.shut_down:  # what SIGINT's handler does while spin makes a wait set
            rclpy.shutdown()
        raise self.error

    def shutdown(self) -> None:
        pass


@pytest.mark.parametrize('error', [
    node_process.RCLError('failed to initialize wait set: the given context is not valid'),
    KeyboardInterrupt()])
def test_shutdown_during_spin_exits_0_and_closes_the_node(monkeypatch: pytest.MonkeyPatch,
                                                          error: BaseException) -> None:
    """The context shut down under spin (rclpy's RCLError, or Ctrl-C): exit code 0."""
    node = _Node()
    monkeypatch.setattr(node_process, 'SingleThreadedExecutor', lambda: _Executor(error, True))
    assert node_process.run_node(lambda: node, 'test_node', args=[]) == node_process.EXIT_OK
    assert node.closed and not rclpy.ok()


def test_an_rcl_error_while_running_is_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    """An RCLError with the context still valid is a real failure: raised, node closed."""
    node = _Node()
    error = node_process.RCLError('something else failed')
    monkeypatch.setattr(node_process, 'SingleThreadedExecutor', lambda: _Executor(error, False))
    with pytest.raises(node_process.RCLError, match='something else'):
        node_process.run_node(lambda: node, 'test_node', args=[])
    assert node.closed and not rclpy.ok()


def test_what_start_up_made_is_frozen_out_of_the_collector(monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    """The node spins with the start-up's objects frozen: full collections skip them."""
    node, frozen = _Node(), []

    class Recording(_Executor):
        def spin(self) -> None:
            frozen.append(gc.get_freeze_count())
            super().spin()

    gc.unfreeze()
    monkeypatch.setattr(node_process, 'SingleThreadedExecutor',
                        lambda: Recording(KeyboardInterrupt(), True))
    try:
        assert node_process.run_node(lambda: node, 'test_node', args=[]) == node_process.EXIT_OK
    finally:
        gc.unfreeze()
    assert frozen and frozen[0] > 0
