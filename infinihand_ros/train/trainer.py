"""The training loop shared by Stage I and Stage II (paper Sec. 3.2-3.3, Sec. 4.1).

``train(config, output)`` builds the model (seeded, or from checkpoints), the clip loader, AdamW
with its parameter groups and the warm-up + cosine schedule, then per step: one batch of clips
through ``ClipRunner`` (wrapped in DistributedDataParallel under ``torchrun``), backward,
global gradient-norm clipping, the optimizer and schedule steps. Rank 0 shows a tqdm bar (loss,
clips/s), appends the loss log, draws the curves, writes a checkpoint every
``checkpoint_every`` steps and at the end (``train_state.py``) and a ``summary.json`` (losses
of the call, every replica's parameter checksum). ``resume`` continues from a
checkpoint exactly as the uninterrupted run would have (weights, optimizer, schedule, data
position and every random state are restored); ``stop_after`` ends the run early (training in
chunks), the schedule still spanning ``config.steps``.
"""

from dataclasses import dataclass
from dataclasses import field
import json
import logging
from pathlib import Path
import random
import time

from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs
from infinihand_ros.model.io.compose import load_composed_model
from infinihand_ros.train import sequence_reader as keys
from infinihand_ros.train.box_jitter import jitter_boxes
from infinihand_ros.train.clip_data import build_clip_loader
from infinihand_ros.train.clip_runner import ClipRunner
from infinihand_ros.train.clip_runner import LOSS
from infinihand_ros.train.distributed import barrier
from infinihand_ros.train.distributed import DistributedContext
from infinihand_ros.train.distributed import gather_objects
from infinihand_ros.train.distributed import init_distributed
from infinihand_ros.train.distributed import mean_values
from infinihand_ros.train.distributed import replica_checksum
from infinihand_ros.train.distributed import shutdown_distributed
from infinihand_ros.train.horizontal_flip import draw_flips
from infinihand_ros.train.horizontal_flip import flip_clips
from infinihand_ros.train.loss_log import LossLog
from infinihand_ros.train.optim import build_optimizer
from infinihand_ros.train.optim import build_scheduler
from infinihand_ros.train.photometric import jitter_photometric
from infinihand_ros.train.train_config import train_config_to_yaml
from infinihand_ros.train.train_config import TrainConfig
from infinihand_ros.train.train_state import capture_rng
from infinihand_ros.train.train_state import checkpoint_name
from infinihand_ros.train.train_state import CHECKPOINTS_DIR
from infinihand_ros.train.train_state import CONFIG_FILE
from infinihand_ros.train.train_state import MODEL_DIR
from infinihand_ros.train.train_state import read_resume_point
from infinihand_ros.train.train_state import restore_rng
from infinihand_ros.train.train_state import ResumePoint
from infinihand_ros.train.train_state import save_training_checkpoint
import numpy as np
import torch
from torch.nn.parallel import DistributedDataParallel
from tqdm import tqdm

logger = logging.getLogger(__name__)

#: Summary of the latest call of ``train`` in the output directory (rank 0 writes it).
SUMMARY_FILE = 'summary.json'
#: Offset of the box-sampling generator's seed per rank (keeps the ranks' draws apart).
_BOX_SEED_STRIDE = 1_000_003


@dataclass(frozen=True)
class TrainResult:
    """What a run did.

    Attributes:
        output: the output directory.
        first_step: the step the run started from (0, or the resumed step).
        last_step: optimizer steps done at the end.
        losses: L_joint of each step of this run (averaged over the ranks).
        checkpoint: the last checkpoint written, or None.
        replica_checksums: ``distributed.replica_checksum`` of every rank at the end.
        seconds_per_step: mean wall time of a step of this run.
        rank: the process's rank (0 writes the outputs).

    """

    output: Path
    first_step: int
    last_step: int
    losses: list[float] = field(default_factory=list)
    checkpoint: Path | None = None
    replica_checksums: list[float] = field(default_factory=list)
    seconds_per_step: float = 0.0
    rank: int = 0


def resolve_device(config: TrainConfig, context: DistributedContext) -> torch.device:
    """Return the run's device (``auto``: CUDA when available; one device per local rank)."""
    use_cuda = config.device == 'cuda' or (config.device == 'auto'
                                           and torch.cuda.is_available())
    return torch.device('cuda', context.local_rank) if use_cuda else torch.device('cpu')


def build_model(config: TrainConfig, init: Path | None = None) -> InfiniHandModel:
    """Return the model to train, in train mode on the CPU.

    Args:
        config: the run (``model`` section).
        init: a whole-model checkpoint to load instead of every checkpoint of ``model``
            (resuming: the run's own weights, nothing on top).

    Raises:
        CheckpointError: for a checkpoint that does not fit the configs.
        ConfigError: for unknown config names or bad values.

    """
    spec = config.model
    geometry_config, hand_config = load_branch_configs(spec.geometry, spec.hand_branch)
    parts = ({'full': init} if init is not None else
             {'full': spec.init_checkpoint, 'geometry': spec.geometry_checkpoint,
              'crop_encoder': spec.crop_encoder_checkpoint})
    if all(path is None for path in parts.values()):
        return build_infinihand_model(geometry_config, hand_config, seed=spec.seed).train()
    model, report = load_composed_model(**parts, geometry_config=geometry_config,
                                        hand_config=hand_config, seed=spec.seed)
    logger.info('initial weights:\n%s', report.describe())
    return model.train()


def _seed_everything(seed: int) -> None:
    """Seed the global torch, numpy and Python generators."""
    torch.manual_seed(seed)
    np.random.seed(seed)
    random.seed(seed)


def _batch_to(batch: dict[str, torch.Tensor], device: torch.device) -> dict[str, torch.Tensor]:
    """Return the batch on ``device``."""
    return {key: value.to(device, non_blocking=True) for key, value in batch.items()}


class _Run:
    """The state of one training process (built by ``train``)."""

    def __init__(self, config: TrainConfig, output: Path, context: DistributedContext,
                 resume: ResumePoint | None) -> None:
        self.config, self.output, self.context = config, output, context
        self.device = resolve_device(config, context)
        _seed_everything(config.seed + context.rank)
        self.step_generator = torch.Generator().manual_seed(
            config.seed + _BOX_SEED_STRIDE * (context.rank + 1))
        self.model = build_model(config, resume.directory / MODEL_DIR if resume else None)
        self.model.to(self.device)
        self.optimizer = build_optimizer(self.model, config.optim)
        self.scheduler = build_scheduler(self.optimizer, config.optim, config.steps)
        self.trainable = [parameter for group in self.optimizer.param_groups
                          for parameter in group['params']]
        self.step = 0
        self.rates: dict[str, float] = {}
        if resume is not None:
            self._restore(resume)
        runner = ClipRunner(self.model, config)
        self.runner = runner if not context.enabled else DistributedDataParallel(
            runner, device_ids=[self.device.index] if self.device.type == 'cuda' else None,
            find_unused_parameters=True)
        self.loader = build_clip_loader(config.data, config.clip, self.model.geometry.config,
                                        config.batch_size, config.seed, context.world_size,
                                        context.rank)
        self.log = LossLog(output, config.log_format, self.step if resume else None) \
            if context.is_main else None

    def _restore(self, resume: ResumePoint) -> None:
        """Load the optimizer, schedule and this rank's random states of a checkpoint."""
        state = resume.state
        self.optimizer.load_state_dict(state['optimizer'])
        self.scheduler.load_state_dict(state['scheduler'])
        states = state['rng']
        if len(states) == self.context.world_size:
            restore_rng(states[self.context.rank], self.step_generator)
        else:
            logger.warning('resuming %d process(es) from a checkpoint of %d: random states '
                           'are reseeded, so the run will not repeat the original exactly',
                           self.context.world_size, len(states))
        self.step = resume.step

    def train_step(self, batch: dict[str, torch.Tensor]) -> tuple[dict[str, torch.Tensor],
                                                                  torch.Tensor]:
        """Run one optimizer step; return the outputs and the gradient norm before clipping."""
        shape = batch[keys.BOX_VALID].shape
        use_gt = torch.rand(shape, generator=self.step_generator) < self.config.gt_box_ratio
        if self.config.box_jitter.enabled:
            batch = {**batch, keys.BOXES: jitter_boxes(batch[keys.BOXES], self.config.box_jitter,
                                                       self.step_generator)}
        if self.config.photometric.enabled:
            batch = {**batch, keys.IMAGES: jitter_photometric(
                batch[keys.IMAGES], self.config.photometric, self.step_generator)}
        if self.config.horizontal_flip > 0.0:
            batch = flip_clips(batch, draw_flips(shape[0], self.config.horizontal_flip,
                                                 self.step_generator))
        batch = _batch_to(batch, self.device)
        outputs = self.runner(batch, use_gt.to(self.device))
        self.optimizer.zero_grad(set_to_none=True)
        outputs[LOSS].backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(self.trainable,
                                                   self.config.optim.grad_clip_norm)
        self.rates = {f'lr.{group["name"]}': group['lr'] for group in self.optimizer.param_groups}
        self.optimizer.step()
        self.scheduler.step()
        self.step += 1
        return outputs, grad_norm

    def record(self, outputs: dict[str, torch.Tensor], grad_norm: torch.Tensor,
               seconds: float) -> dict[str, float]:
        """Return the log record of the step (values averaged over the ranks)."""
        values = mean_values(self.context, {**outputs, 'grad_norm': grad_norm}, self.device)
        clips = self.config.batch_size * self.context.world_size
        return {'step': self.step, **values, **self.rates, 'clips_per_s': clips / seconds}

    def checkpoint(self) -> Path:
        """Write the checkpoint of the current step (rank 0 writes; every rank gives RNG)."""
        states = gather_objects(self.context, capture_rng(self.step_generator))
        final = self.step == self.config.steps
        directory = self.output / CHECKPOINTS_DIR / checkpoint_name(self.step, final)
        if self.context.is_main:
            save_training_checkpoint(directory, self.model, self.optimizer, self.scheduler,
                                     self.config, self.step, states,
                                     self.loader.position(self.step))
            self.log.write_curves()
        barrier(self.context)
        return directory


def _loop(run: _Run, end_step: int, progress: bool) -> TrainResult:
    """Train from ``run.step`` to ``end_step``; return the result."""
    config, first_step = run.config, run.step
    losses, checkpoint, elapsed = [], None, 0.0
    bar = tqdm(total=end_step, initial=first_step, desc=config.stage, unit='step',
               disable=not (progress and run.context.is_main), dynamic_ncols=True)
    batches = run.loader.batches(first_step)
    try:
        while run.step < end_step:
            start = time.perf_counter()
            outputs, grad_norm = run.train_step(next(batches))
            seconds = time.perf_counter() - start
            elapsed += seconds
            record = run.record(outputs, grad_norm, seconds)
            losses.append(record[LOSS])
            if run.log is not None and (run.step % config.log_every == 0
                                        or run.step == end_step):
                run.log.append(record)
            bar.update(1)
            bar.set_postfix(loss=f'{record[LOSS]:.4g}', clips_s=f'{record["clips_per_s"]:.2f}')
            if run.step % config.checkpoint_every == 0 or run.step == end_step:
                checkpoint = run.checkpoint()
    finally:
        batches.close()
        bar.close()
    checksums = gather_objects(run.context, replica_checksum(run.model))
    result = TrainResult(run.output, first_step, run.step, losses, checkpoint, checksums,
                         elapsed / max(1, len(losses)), run.context.rank)
    if run.context.is_main:
        summary = {'first_step': first_step, 'last_step': run.step, 'losses': losses,
                   'checkpoint': None if checkpoint is None else str(checkpoint),
                   'replica_checksums': checksums, 'seconds_per_step': result.seconds_per_step,
                   'processes': run.context.world_size}
        atomic_write_bytes(run.output / SUMMARY_FILE, json.dumps(summary, indent=2).encode())
    return result


def train(config: TrainConfig, output: str | Path, resume: str | Path | None = None,
          stop_after: int | None = None, progress: bool = True) -> TrainResult:
    """Train ``config`` into ``output`` (see the module docstring).

    Args:
        config: the resolved run config.
        output: directory of the log, curves, checkpoints and ``train_config.yaml``.
        resume: a checkpoint, or an output directory (its newest checkpoint), to continue.
        stop_after: train at most this many steps in this call (None: to ``config.steps``).
        progress: show the progress bar (rank 0).

    Raises:
        CheckpointError: for an unreadable resume or initial checkpoint.
        ConfigError: for a config that does not fit the model or data.
        InputError: for missing or unusable training data.

    """
    output = Path(output)
    context = init_distributed(resolve_device(config, DistributedContext()).type == 'cuda')
    threads = torch.get_num_threads()
    try:
        if config.cpu_threads:
            torch.set_num_threads(config.cpu_threads)  # the caller's count is put back below
        point = read_resume_point(resume) if resume is not None else None
        if context.is_main:
            output.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(output / CONFIG_FILE, train_config_to_yaml(config).encode())
        run = _Run(config, output, context, point)
        end_step = config.steps if stop_after is None else min(config.steps,
                                                               run.step + stop_after)
        result = _loop(run, end_step, progress)
        barrier(context)  # every rank is done before the group is torn down
        del run  # DDP's reducer goes before its process group (see shutdown_distributed)
        return result
    finally:
        torch.set_num_threads(threads)
        shutdown_distributed(context)
