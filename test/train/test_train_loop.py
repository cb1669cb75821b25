"""The training loop: it learns, resumes bit-for-bit and writes its log, curves and checkpoints."""

from collections.abc import Callable
import json
import math
from pathlib import Path

from infinihand_ros.model.io.compose import load_infinihand_checkpoint
from infinihand_ros.train.loss_log import CURVES_FILE
from infinihand_ros.train.loss_log import JSONL_FILE
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_state import CHECKPOINTS_DIR
from infinihand_ros.train.train_state import CONFIG_FILE
from infinihand_ros.train.train_state import MODEL_DIR
from infinihand_ros.train.trainer import SUMMARY_FILE
from infinihand_ros.train.trainer import train
import numpy as np
import pytest
import torch


def _log(output: Path) -> list[dict]:
    return [json.loads(line) for line in (output / JSONL_FILE).read_text().splitlines()]


def test_stage1_overfits_one_clip(write_run_config: Callable[..., Path], tmp_path: Path,
                                  sequence_dirs: list[Path]) -> None:
    """Repeating one 4-frame clip (ground-truth boxes), L_joint falls within a few steps."""
    config = load_train_config(write_run_config(
        stage='stage1', loss_groups=['mask', 'landmarks', 'mano'],
        clip={'anchor_frames': 4, 'window_frames': 0, 'num_windows': 0, 'clip_step': 100},
        data={'sequences': [str(sequence_dirs[0])]}, gt_box_ratio=1.0, steps=8,
        checkpoint_every=100,
        optim={'groups': [{'name': 'all', 'prefixes': [''], 'lr': 2.0e-3}],
               'frozen': ['geometry.camera_head', 'geometry.depth_head'], 'warmup_steps': 1,
               'min_lr_ratio': 0.5}))
    result = train(config, tmp_path / 'run', progress=False)
    losses = result.losses
    assert len(losses) == 8 and all(math.isfinite(loss) for loss in losses)
    assert min(losses[-2:]) < 0.8 * losses[0], losses
    record = _log(tmp_path / 'run')[-1]
    assert record['step'] == 8 and {'mask.bce', 'landmarks.l1', 'mano.reproj', 'grad_norm',
                                    'lr.all', 'clips_per_s'} <= set(record)
    assert 'camera.total' not in record


def test_resume_continues_bit_for_bit(write_run_config: Callable[..., Path],
                                      tmp_path: Path) -> None:
    """Stage II, 6 steps in one go == 3 steps, then resume for 3: identical losses.

    The boxes are jittered, so the box generator's state must survive the checkpoint too.
    """
    config = load_train_config(write_run_config(steps=6, checkpoint_every=3,
                                                box_jitter={'scale': 0.3, 'shift': 0.1}))
    whole = train(config, tmp_path / 'whole', progress=False)
    first = train(config, tmp_path / 'split', stop_after=3, progress=False)
    assert first.checkpoint == tmp_path / 'split' / CHECKPOINTS_DIR / 'step_0000003'
    second = train(config, tmp_path / 'split', resume=tmp_path / 'split', progress=False)
    assert (first.last_step, second.first_step, second.last_step) == (3, 3, 6)
    assert first.losses + second.losses == whole.losses
    assert [record['loss'] for record in _log(tmp_path / 'split')] == whole.losses
    assert second.replica_checksums == whole.replica_checksums


def test_outputs_of_a_run(write_run_config: Callable[..., Path], tmp_path: Path) -> None:
    """Checkpoints (loadable model, state, config), log, curves and summary are written."""
    config = load_train_config(write_run_config(steps=2, checkpoint_every=1))
    output = tmp_path / 'run'
    result = train(config, output, progress=False)
    checkpoints = sorted(path.name for path in (output / CHECKPOINTS_DIR).iterdir())
    assert checkpoints == ['final', 'step_0000001']
    final = output / CHECKPOINTS_DIR / 'final'
    assert load_train_config(final / CONFIG_FILE) == config
    assert load_train_config(output / CONFIG_FILE) == config
    model, _ = load_infinihand_checkpoint(final / MODEL_DIR)
    assert model.geometry.config.aggregator.image_width == 70
    assert result.checkpoint == final
    curves = output / CURVES_FILE
    assert curves.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    summary = json.loads((output / SUMMARY_FILE).read_text())
    assert summary['losses'] == result.losses and summary['processes'] == 1
    assert all(np.isfinite(record['loss']) for record in _log(output))


def test_batches_of_several_clips_train(write_run_config: Callable[..., Path],
                                        tmp_path: Path) -> None:
    """B = 2 clips in one stream per step (CSV log)."""
    config = load_train_config(write_run_config(batch_size=2, steps=1, log_format='csv'))
    result = train(config, tmp_path / 'run', progress=False)
    assert math.isfinite(result.losses[0])
    header = (tmp_path / 'run' / 'loss_log.csv').read_text().splitlines()[0]
    assert header.startswith('step,') and 'camera.rel_pose' in header


@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_a_cuda_step_runs(write_run_config: Callable[..., Path], tmp_path: Path) -> None:
    config = load_train_config(write_run_config(steps=1, device='cuda'))
    assert math.isfinite(train(config, tmp_path / 'run', progress=False).losses[0])
