"""The live run's settings and topics (tools/live_run.py)."""

from pathlib import Path

from infinihand_ros.core.errors import InfiniHandError
import pytest

live_run = pytest.importorskip('infinihand_ros.tools.live_run', reason='needs rclpy')

pytestmark = pytest.mark.ros


def test_bad_bundle_adjustment_mode_is_named() -> None:
    """Only the node's modes are accepted."""
    with pytest.raises(InfiniHandError, match="got 'always'"):
        live_run.LiveRunSpec(Path('bag'), Path('rec'), Path('logs'), 1.0, 0.0, 'always')


def test_the_synthetic_sample_runs_the_branch_and_a_bad_source_is_named() -> None:
    """The live run's default hand source is infinihand (our bags are synthetic)."""
    spec = live_run.LiveRunSpec(Path('bag'), Path('rec'), Path('logs'), 1.0, 0.0)
    assert spec.hand_source == 'infinihand'
    with pytest.raises(InfiniHandError, match="got 'opencv'"):
        live_run.LiveRunSpec(Path('bag'), Path('rec'), Path('logs'), 1.0, 0.0, 'none', 'opencv')


def test_recorded_topics_are_the_estimator_outputs() -> None:
    """Camera pose and both landmark arrays under the node, the images, /diagnostics."""
    assert live_run.recorded_topics().names() == [
        '/infinihand_estimator/camera_pose', '/infinihand_estimator/hands/left/landmarks',
        '/infinihand_estimator/hands/right/landmarks', '/camera/image_raw/compressed',
        '/diagnostics']
