"""Independent validators on a converted mixed-size dataset: lerobot-doctor and physlint.

Nothing is installed at run time: each test runs when its validator is installed (both are
pinned in requirements.txt). Neither may report a failure. What they warn about, and why it
is expected of hand demonstrations converted by a model (checked on the sample bag plus the real
640x480 stills: 7 PASS, 4 WARN, 0 FAIL):

- Data Distribution / Anomaly Detection: constant dimensions. The last row of
  ``camera.T_world_cam`` is always (0, 0, 0, 1), the wrist's own coordinates in
  ``hands.keypoints_wrist`` are always 0, and ``camera.flags[keyframe]`` is 1 on every frame
  in windowed mode.
- Episode Health: episodes shorter than ACT's chunk of 50 frames (short inputs).
- Training Readiness: a 48-dim action (two hands of wrist position, 6D rotation and five
  fingertips: the layout, not an error).

physlint on the estimates MCAP passes every rule it can run (the ROS-topic rules it cannot run
without a contract stay 'not_run').
"""

import json
from pathlib import Path
import subprocess
import sys

from convert_builders import BASE_NS
from convert_builders import fast_config
from convert_builders import image_bag
from convert_builders import PERIOD_NS
from infinihand_ros.convert.cli import EXIT_OK
from infinihand_ros.convert.cli import main
import numpy as np
import pytest

BIN = Path(sys.executable).parent


def _dataset(tmp_path: Path) -> Path:
    rng = np.random.default_rng(0)
    inputs = []
    for name, size, period in (('a', (160, 120), PERIOD_NS), ('b', (200, 100), PERIOD_NS // 2)):
        inputs.append(image_bag(tmp_path / name, [
            (BASE_NS + k * period, 'rgb8', rng.integers(0, 256, (size[1], size[0], 3), np.uint8))
            for k in range(6)]))
    output = tmp_path / 'dataset'
    config = fast_config(tmp_path / 'convert.yaml')
    assert main([*map(str, inputs), '--output', str(output), '--config', str(config),
                 '--quiet']) == EXIT_OK
    return output


def _run_json(command: list[str], cwd: Path) -> dict:
    """Run a validator in ``cwd`` (physlint keeps a .physlint/ cache in its working folder)."""
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=cwd)
    return json.loads(run.stdout)


@pytest.mark.slow
def test_lerobot_doctor_and_physlint_find_no_failure(tmp_path: Path) -> None:
    pytest.importorskip('lerobot_doctor')
    output = _dataset(tmp_path)
    doctor = _run_json([str(BIN / 'lerobot-doctor'), 'check', str(output), '--json'], tmp_path)
    assert doctor['total_episodes'] == 2
    failed = [check for check in doctor['checks'] if check['severity'] == 'FAIL']
    assert not failed, failed
    pytest.importorskip('physlint')
    for path in [output, *sorted((output / 'estimates').iterdir())]:
        report = _run_json([str(BIN / 'physlint'), 'check', str(path), '--format', 'json'],
                           tmp_path)
        failed = [r for r in report['results'] if r['status'] not in ('passed', 'not_run')]
        assert report['status'] == 'passed' and not failed, (path, failed)
