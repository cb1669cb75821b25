"""The estimator's link state to the BA node (ros/estimator/ba_link.py)."""

from infinihand_ros.ros.estimator.ba_node_client import BANodeLink
from infinihand_ros.ros.estimator.diagnostics import CONNECTED
from infinihand_ros.ros.estimator.diagnostics import LOST
from infinihand_ros.ros.estimator.diagnostics import WAITING
import numpy as np


def test_waiting_connected_lost_and_back() -> None:
    """States follow the heartbeats; each change is reported once; outages are counted."""
    link = BANodeLink(timeout_s=3.0, stamps_kept=8)
    assert link.state(0.0) == WAITING and link.changed(0.0) is None
    link.heard(1.0, 'idle')
    assert link.changed(1.5) == CONNECTED and link.changed(2.0) is None
    assert link.state(4.0) == CONNECTED
    assert link.changed(4.1) == LOST and link.changed(9.0) is None
    link.heard(10.0, 'running')
    assert link.changed(10.0) == CONNECTED
    statistics = link.statistics(10.0)
    assert statistics['state'] == CONNECTED and statistics['node_state'] == 'running'
    assert statistics['outages'] == 1


def test_only_results_of_sent_keyframes_are_accepted() -> None:
    """Stamps sent (the last few kept) are accepted; others are refused and counted."""
    link = BANodeLink(timeout_s=1.0, stamps_kept=3)
    for stamp in (10, 20, 30, 40):
        link.sent(stamp)
    assert link.accepts(np.array([20, 40]))
    assert not link.accepts(np.array([10, 20]))  # 10 was forgotten
    assert not link.accepts(np.array([99]))
    statistics = link.statistics(0.0)
    assert statistics['results_refused'] == 2 and statistics['keyframes_sent'] == 4


def test_results_of_a_stream_before_a_restart_are_refused() -> None:
    """forget_sent: results of keyframes sent before are refused; new keyframes are accepted."""
    link = BANodeLink(timeout_s=1.0, stamps_kept=8)
    for stamp in (10, 20):
        link.sent(stamp)
    link.forget_sent()
    assert not link.accepts(np.array([10, 20]))
    link.sent(10)  # a replay loop sends the same stamps again
    assert link.accepts(np.array([10]))
    assert link.statistics(0.0)['keyframes_sent'] == 3
