"""Configuration of a training run (paper Sec. 3.2-3.3, Sec. 4.1): ``config/train_*.yaml``.

A training file has two top-level sections: ``train`` (the ``TrainConfig`` fields below, nested
sections included) and ``losses`` (the ``LossConfig`` of ``config/train_losses.yaml``, whose
values are used when the file has no ``losses`` section), and may name a ``base`` file it
overrides (``config_compose.py``). ``load_train_config`` composes the file, applies dotted
overrides and reads both sections into one frozen ``TrainConfig``; ``train_config_to_yaml``
writes the resolved configuration back in the same form (every field, no base), as saved
beside each checkpoint.

Stage I trains the camera-space heads on short clips (mask, 2D landmark and MANO losses);
Stage II trains jointly on anchors + windows with every loss group of L_joint. Which
parameters train, and at which learning rate, is the ``optim`` section: parameters go to the
first group one of whose prefixes starts their name (prefix ``''`` matches all); names under a
``frozen`` prefix do not train; a trainable name in no group is refused when the run starts.
"""

from collections.abc import Mapping
import dataclasses
from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Any
from typing import Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import config_to_dict
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.box_jitter import BoxJitter
from infinihand_ros.train.config_compose import apply_overrides
from infinihand_ros.train.config_compose import BASE_KEY
from infinihand_ros.train.config_compose import read_composed
from infinihand_ros.train.losses import load_loss_config
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import LOSSES_SECTION
from infinihand_ros.train.losses.loss_config import LOSSES_FILE
from infinihand_ros.train.photometric import PhotometricJitter
import yaml

#: Top-level section of a training file holding the ``TrainConfig`` fields.
TRAIN_SECTION: Final = 'train'
#: Values of ``TrainConfig.stage``.
STAGE_1: Final = 'stage1'
STAGE_2: Final = 'stage2'
STAGES: Final = (STAGE_1, STAGE_2)
#: Loss groups of L_joint (Sec. 3.3), the names of ``TrainConfig.loss_groups``.
LOSS_GROUPS: Final = ('mask', 'landmarks', 'mano', 'world_joints', 'camera', 'temporal',
                      'depth')
#: Groups that need world-space predictions (camera poses), so Stage II only.
WORLD_GROUPS: Final = ('world_joints', 'camera')
#: Values of ``TrainConfig.log_format``.
LOG_FORMATS: Final = ('jsonl', 'csv')
#: Values of ``TrainConfig.device``.
DEVICES: Final = ('auto', 'cpu', 'cuda')


@dataclass(frozen=True)
class ModelSpec:
    """Which model to train and where its initial weights come from.

    Attributes:
        geometry: geometry-branch config, a name (``tiny``, ``paper``) or a YAML path.
        hand_branch: hand-branch config, a name or a YAML path.
        seed: seed of every weight no checkpoint provides.
        init_checkpoint: a whole-model checkpoint directory to start from (e.g. Stage I's
            result for Stage II), or null.
        geometry_checkpoint: converted LingBot-Map weights for the geometry branch, or null.
        crop_encoder_checkpoint: converted WiLoR weights for the crop encoder, or null.

    """

    geometry: str = 'tiny'
    hand_branch: str = 'tiny'
    seed: int = 0
    init_checkpoint: str | None = None
    geometry_checkpoint: str | None = None
    crop_encoder_checkpoint: str | None = None


@dataclass(frozen=True)
class ClipLayout:
    """Frames of one training clip: an anchor block, then ``num_windows`` windows.

    The model sees the anchors in one call and each window in one call, its streaming state
    carried across the calls of a clip and reset between clips (paper: 4 + 16 x 2).

    Attributes:
        anchor_frames: frames of the first call (Stage I: the whole 4-frame clip).
        window_frames: frames of each later call.
        num_windows: later calls (0: the clip is the anchor block only).
        frame_stride: sequence frames between consecutive clip frames.
        clip_step: sequence frames between the first frames of two clips of one sequence.

    """

    anchor_frames: int = 4
    window_frames: int = 16
    num_windows: int = 2
    frame_stride: int = 1
    clip_step: int = 1

    def __post_init__(self) -> None:
        """Refuse empty blocks and non-positive strides (ConfigError naming the key)."""
        owner = f'{TRAIN_SECTION}.clip'
        require_positive(owner, anchor_frames=self.anchor_frames,
                         frame_stride=self.frame_stride, clip_step=self.clip_step)
        require_at_least(owner, 0, num_windows=self.num_windows)
        if self.num_windows:
            require_positive(owner, window_frames=self.window_frames)

    @property
    def total_frames(self) -> int:
        """Return the clip length S = anchors + windows x window frames."""
        return self.anchor_frames + self.num_windows * self.window_frames

    @property
    def blocks(self) -> tuple[tuple[int, int], ...]:
        """Return each call's (first, end) clip-frame range, the anchors first."""
        ranges = [(0, self.anchor_frames)]
        for window in range(self.num_windows):
            start = self.anchor_frames + window * self.window_frames
            ranges.append((start, start + self.window_frames))
        return tuple(ranges)


@dataclass(frozen=True)
class DataConfig:
    """Training sequences and the loader.

    Attributes:
        sequences: sequence directories, or directories searched (recursively) for them;
            relative paths are relative to the working directory.
        num_workers: DataLoader worker processes (0: load in the training process).
        cache_images: keep each decoded, model-size frame in memory (per worker process).

    """

    sequences: tuple[str, ...] = ()
    num_workers: int = 2
    cache_images: bool = False

    def __post_init__(self) -> None:
        """Refuse a negative worker count (ConfigError naming the key)."""
        require_at_least(f'{TRAIN_SECTION}.data', 0, num_workers=self.num_workers)


@dataclass(frozen=True)
class ParamGroupConfig:
    """One optimizer parameter group.

    Attributes:
        name: label in logs.
        prefixes: parameter-name prefixes of the group (``''`` matches every name).
        lr: peak learning rate (after warm-up).

    """

    name: str = 'all'
    prefixes: tuple[str, ...] = ('',)
    lr: float = 1.0e-5

    def __post_init__(self) -> None:
        """Refuse a group without prefixes or a non-positive rate."""
        owner = f'{TRAIN_SECTION}.optim.groups[{self.name}]'
        require_positive(owner, lr=self.lr)
        if not self.prefixes:
            raise ConfigError(f"{owner}.prefixes: give at least one prefix ('' for all)")


@dataclass(frozen=True)
class OptimConfig:
    """AdamW, linear warm-up + cosine annealing, global gradient-norm clipping (Sec. 4.1).

    Attributes:
        groups: parameter groups, matched in order.
        frozen: parameter-name prefixes that do not train (checked before the groups).
        weight_decay: AdamW decoupled weight decay (paper: 0.01).
        betas: AdamW (beta1, beta2).
        eps: AdamW epsilon.
        warmup_steps: steps of the linear warm-up from ~0 to each group's rate.
        min_lr_ratio: the cosine ends at this fraction of each group's rate.
        grad_clip_norm: global L2 norm the gradients are clipped to (paper: 1.0).

    """

    groups: tuple[ParamGroupConfig, ...] = (ParamGroupConfig(),)
    frozen: tuple[str, ...] = ()
    weight_decay: float = 0.01
    betas: tuple[float, float] = (0.9, 0.999)
    eps: float = 1.0e-8
    warmup_steps: int = 0
    min_lr_ratio: float = 0.0
    grad_clip_norm: float = 1.0

    def __post_init__(self) -> None:
        """Refuse values that break the optimizer or schedule (ConfigError naming the key)."""
        owner = f'{TRAIN_SECTION}.optim'
        require_at_least(owner, 0.0, weight_decay=self.weight_decay,
                         warmup_steps=self.warmup_steps, min_lr_ratio=self.min_lr_ratio)
        require_positive(owner, eps=self.eps, grad_clip_norm=self.grad_clip_norm)
        if not self.groups:
            raise ConfigError(f'{owner}.groups: give at least one parameter group')
        if not all(0.0 <= beta < 1.0 for beta in self.betas):
            raise ConfigError(f'{owner}.betas: each must be in [0, 1), got {self.betas!r}')
        if self.min_lr_ratio > 1.0:
            raise ConfigError(f'{owner}.min_lr_ratio: must be <= 1, got {self.min_lr_ratio!r}')
        names = [group.name for group in self.groups]
        if len(set(names)) != len(names):
            raise ConfigError(f'{owner}.groups: names must differ, got {names}')


@dataclass(frozen=True)
class TrainConfig:
    """One training run (section ``train``; ``losses`` from the file's ``losses`` section).

    Attributes:
        stage: ``stage1`` (camera-space heads) or ``stage2`` (joint streaming training).
        model: the model and its initial weights.
        clip: the clip layout.
        data: sequences and loader.
        optim: optimizer, schedule, parameter groups, frozen parameters.
        loss_groups: the terms of L_joint summed (Stage I: mask, landmarks, mano).
        batch_size: clips per optimizer step and process (the global batch is this times the
            number of processes).
        steps: optimizer steps of the whole run (the schedule's length).
        seed: seed of the data order and the per-step draws (boxes, colour jitter, flips).
        gt_box_ratio: probability that a visible hand runs on its ground-truth box rather than
            the predicted one (paper Stage II: 0.5; Stage I: 1.0).
        box_jitter: random scale and shift of the ground-truth boxes (ours; off by default).
        photometric: random brightness, contrast and saturation per clip (ours; off by
            default).
        horizontal_flip: probability that a clip is mirrored left-right, sides swapped (ours;
            ``horizontal_flip.py``; 0: off).
        peak_region_boxes: predicted boxes cover only the region around each mask's peak, as
            the engine's ``detection.peak_region`` without its ``region_join_px`` (ours; off by
            default).
        use_gt_intrinsics: run the hand branch with the annotated intrinsics (else the
            predicted ones).
        mask_logit_eps: mask probabilities are clamped to [eps, 1 - eps] before ``logit``
            gives the mask loss its logits (the model returns probabilities).
        checkpoint_every: steps between checkpoints (the last step always writes one).
        log_every: steps between loss-log lines.
        log_format: ``jsonl`` or ``csv`` loss log.
        device: ``auto`` (CUDA when available), ``cpu`` or ``cuda``. On CUDA the aggregator
            runs in bf16 autocast as the geometry config's ``autocast_bf16`` says (the engine's
            forward pass); the heads and the hand branch stay float32.
        cpu_threads: torch CPU threads of each process (0: torch's default). 1 is much faster
            when the CPU is shared (busy-waiting threads of a contended machine).
        losses: loss weights (the file's top-level ``losses`` section).

    """

    stage: str = STAGE_1
    model: ModelSpec = field(default_factory=ModelSpec)
    clip: ClipLayout = field(default_factory=ClipLayout)
    data: DataConfig = field(default_factory=DataConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    loss_groups: tuple[str, ...] = ('mask', 'landmarks', 'mano')
    batch_size: int = 1
    steps: int = 1
    seed: int = 0
    gt_box_ratio: float = 1.0
    box_jitter: BoxJitter = field(default_factory=BoxJitter)
    photometric: PhotometricJitter = field(default_factory=PhotometricJitter)
    horizontal_flip: float = 0.0
    peak_region_boxes: bool = False
    use_gt_intrinsics: bool = True
    mask_logit_eps: float = 1.0e-6
    checkpoint_every: int = 1000
    log_every: int = 1
    log_format: str = 'jsonl'
    device: str = 'auto'
    cpu_threads: int = 0
    losses: LossConfig = field(default_factory=LossConfig)

    def __post_init__(self) -> None:
        """Refuse inconsistent settings (ConfigError naming the key and the value)."""
        owner = TRAIN_SECTION
        _require_choice(f'{owner}.stage', self.stage, STAGES)
        _require_choice(f'{owner}.log_format', self.log_format, LOG_FORMATS)
        _require_choice(f'{owner}.device', self.device, DEVICES)
        require_positive(owner, batch_size=self.batch_size, steps=self.steps,
                         checkpoint_every=self.checkpoint_every, log_every=self.log_every,
                         mask_logit_eps=self.mask_logit_eps)
        require_at_least(owner, 0, seed=self.seed, cpu_threads=self.cpu_threads)
        if not 0.0 <= self.gt_box_ratio <= 1.0:
            raise ConfigError(f'{owner}.gt_box_ratio: must be in [0, 1], got '
                              f'{self.gt_box_ratio!r}')
        if not 0.0 <= self.horizontal_flip <= 1.0:
            raise ConfigError(f'{owner}.horizontal_flip: must be a probability in [0, 1], got '
                              f'{self.horizontal_flip!r}')
        if not self.mask_logit_eps < 0.5:
            raise ConfigError(f'{owner}.mask_logit_eps: must be below 0.5, got '
                              f'{self.mask_logit_eps!r}')
        if not self.loss_groups:
            raise ConfigError(f'{owner}.loss_groups: give at least one of {list(LOSS_GROUPS)}')
        for name in self.loss_groups:
            _require_choice(f'{owner}.loss_groups', name, LOSS_GROUPS)
        world = sorted(set(self.loss_groups) & set(WORLD_GROUPS))
        if self.stage == STAGE_1 and world:
            raise ConfigError(f'{owner}.loss_groups: {world} need Stage II (camera poses over '
                              f'a clip); use stage: {STAGE_2} or drop them')


#: The dataclass of each top-level section of a training file (the roots of dotted overrides).
SECTION_CONFIGS: Final = {TRAIN_SECTION: TrainConfig, LOSSES_SECTION: LossConfig}


def _require_choice(where: str, value: str, choices: tuple[str, ...]) -> None:
    """Raise ConfigError unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ConfigError(f'{where}: must be one of {list(choices)}, got {value!r}')


def named_train_config_path(name: str) -> Path:
    """Return ``config/train_<name>.yaml`` of the package (e.g. ``tiny`` or ``paper``)."""
    return config_dir() / f'train_{name}.yaml'


def load_train_config(path: str | Path,
                      overrides: Mapping[str, Any] | None = None) -> TrainConfig:
    """Load a training file: its base chain, then ``overrides``, then ``train`` and ``losses``.

    Args:
        path: the YAML file, or a shipped name (``tiny``, ``paper``).
        overrides: dotted keys and values set after composition (``{'train.steps': 500}``),
            as ``train --set`` gives them.

    Raises:
        ConfigError: for a missing or unreadable file, a missing ``train`` section, an unknown
            key, a wrong type or a rejected value, naming the dotted key.

    """
    text = str(path)
    path = Path(text) if text.endswith(('.yaml', '.yml')) else named_train_config_path(text)
    document = read_composed(path)
    if overrides:
        document = apply_overrides(document, overrides, SECTION_CONFIGS)
    if TRAIN_SECTION not in document:
        raise ConfigError(f'{path}: no top-level section {TRAIN_SECTION!r}')
    unknown = sorted(set(document) - {TRAIN_SECTION, LOSSES_SECTION})
    if unknown:
        raise ConfigError(f'{path}: unknown top-level key(s) {unknown}; valid keys are '
                          f'{sorted((BASE_KEY, LOSSES_SECTION, TRAIN_SECTION))}')
    section = document[TRAIN_SECTION]
    if isinstance(section, dict) and LOSSES_SECTION in section:
        raise ConfigError(f'{path}:{TRAIN_SECTION}.{LOSSES_SECTION}: put the loss weights in a '
                          f'top-level {LOSSES_SECTION!r} section (as in {LOSSES_FILE})')
    config = config_from_dict(TrainConfig, section, f'{path}:{TRAIN_SECTION}')
    if LOSSES_SECTION in document:
        losses = config_from_dict(LossConfig, document[LOSSES_SECTION],
                                  f'{path}:{LOSSES_SECTION}')
    else:
        losses = load_loss_config()
    return dataclasses.replace(config, losses=losses)


def train_config_to_yaml(config: TrainConfig) -> str:
    """Return the YAML text (sections ``train`` and ``losses``) that loads back to ``config``."""
    train = config_to_dict(config)
    losses = train.pop(LOSSES_SECTION)
    return yaml.safe_dump({TRAIN_SECTION: train, LOSSES_SECTION: losses}, sort_keys=False)
