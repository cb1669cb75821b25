"""Training clips over any number of sequences, and their deterministic, resumable loader.

``ClipDataset`` indexes every clip (start frame, then ``clip.total_frames`` frames
``frame_stride`` apart, starts ``clip_step`` apart) of every sequence, builds each sequence's
targets once (``sequence_reader.build_targets``) and per item only decodes and fits the clip's
images and masks (optionally cached per process). ``ResumableSampler`` is a
``DistributedSampler`` (one replica when not distributed) that can start mid-epoch, so a
resumed run reads exactly the clips the uninterrupted run would have read; ``ClipLoader`` turns
a global step into (epoch, batch) and back. The item order depends only on the seed, the epoch
and the number of processes, never on the worker count.
"""

from collections.abc import Iterator
from collections.abc import Mapping
from pathlib import Path

from infinihand_ros.core.errors import InputError
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.train import sequence_reader as keys
from infinihand_ros.train.sequence_reader import build_targets
from infinihand_ros.train.sequence_reader import find_sequences
from infinihand_ros.train.sequence_reader import FrameFitter
from infinihand_ros.train.sequence_reader import open_sequence
from infinihand_ros.train.sequence_reader import ReaderFactory
from infinihand_ros.train.sequence_reader import SAMPLE_READERS
from infinihand_ros.train.sequence_reader import SequenceReader
from infinihand_ros.train.train_config import ClipLayout
from infinihand_ros.train.train_config import DataConfig
import numpy as np
import torch
from torch.utils.data import DataLoader
from torch.utils.data import Dataset
from torch.utils.data.distributed import DistributedSampler


class ClipDataset(Dataset):
    """Clips of ``layout.total_frames`` frames with their targets, as dicts of tensors.

    Each item holds the ``sequence_reader`` keys with a leading clip-frame axis S (images and
    masks uint8 at the model size, targets float64 / bool), plus ``frame_index`` (S,) and
    ``sequence_index`` ().
    """

    def __init__(self, sequences: list[str | Path], layout: ClipLayout, config: GeometryConfig,
                 readers: Mapping[str, ReaderFactory] = SAMPLE_READERS,
                 cache_images: bool = False) -> None:
        """Open the sequences, build their targets and index their clips.

        Args:
            sequences: sequence directories (``find_sequences`` resolves folders of them).
            layout: the clip layout.
            config: the model's geometry config (input size, preprocessing).
            readers: reader factories by format name.
            cache_images: keep decoded, fitted frames in memory (per process).

        Raises:
            InputError: for an unreadable sequence or when no sequence is long enough.

        """
        self.layout = layout
        self.fitter = FrameFitter(config)
        self.readers: list[SequenceReader] = [open_sequence(path, readers)
                                              for path in sequences]
        self.paths = [Path(path) for path in sequences]
        self.targets = []
        span = (layout.total_frames - 1) * layout.frame_stride + 1
        self.clips: list[tuple[int, int]] = []
        for index, reader in enumerate(self.readers):
            has_masks = reader.read_hand_labels(0) is not None if reader.num_frames else False
            self.targets.append({key: torch.from_numpy(np.ascontiguousarray(value))
                                 for key, value in build_targets(reader, config,
                                                                 has_masks).items()})
            self.clips.extend((index, start) for start in
                              range(0, reader.num_frames - span + 1, layout.clip_step))
        if not self.clips:
            lengths = [reader.num_frames for reader in self.readers]
            raise InputError(f'training data: no sequence holds a clip of {span} frames '
                             f'(layout {layout.total_frames} frames, stride '
                             f'{layout.frame_stride}); sequence lengths are {lengths}')
        self._cache: dict[tuple[int, int], tuple[np.ndarray | None, ...]] | None = (
            {} if cache_images else None)

    def __len__(self) -> int:
        """Return the number of clips over all sequences."""
        return len(self.clips)

    def __getitem__(self, item: int) -> dict[str, torch.Tensor]:
        """Return clip ``item``: decoded images and masks plus the prepared targets."""
        sequence, start = self.clips[item]
        frames = start + self.layout.frame_stride * np.arange(self.layout.total_frames)
        images, masks, depths = zip(*(self._frame(sequence, int(frame)) for frame in frames))
        index = torch.from_numpy(frames.astype(np.int64))
        clip = {key: value[index] for key, value in self.targets[sequence].items()}
        clip[keys.IMAGES] = torch.from_numpy(np.stack(images))
        height, width = images[0].shape[-2:]
        clip[keys.MASKS] = torch.from_numpy(np.stack(
            [np.zeros((2, height, width), np.uint8) if mask is None else mask
             for mask in masks]))
        clip[keys.DEPTH] = torch.from_numpy(np.stack(
            [np.zeros((height, width), np.float32) if depth is None else depth
             for depth in depths]))
        clip[keys.FRAME_INDEX] = index
        clip[keys.SEQUENCE_INDEX] = torch.tensor(sequence, dtype=torch.long)
        return clip

    def _frame(self, sequence: int, frame: int
               ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Return the fitted (3, H, W) image, (2, H, W) masks and (H, W) depth (or None)."""
        if self._cache is not None and (sequence, frame) in self._cache:
            return self._cache[(sequence, frame)]
        reader = self.readers[sequence]
        labels = reader.read_hand_labels(frame)
        depth = reader.read_depth(frame)
        fitted = (self.fitter.fit_rgb(reader.read_rgb(frame)),
                  None if labels is None else self.fitter.fit_masks(labels),
                  None if depth is None else self.fitter.fit_depth(depth))
        if self._cache is not None:
            self._cache[(sequence, frame)] = fitted
        return fitted


class ResumableSampler(DistributedSampler):
    """``DistributedSampler`` that can start at any position of an epoch.

    With ``num_replicas=1, rank=0`` it needs no process group, so single-process runs use the
    same order as one replica of a distributed run would.
    """

    def __init__(self, dataset: Dataset, num_replicas: int, rank: int, seed: int) -> None:
        """Shuffle with ``seed`` (+ epoch), drop the tail so every replica gets as many."""
        super().__init__(dataset, num_replicas=num_replicas, rank=rank, shuffle=True,
                         seed=seed, drop_last=True)
        self.start_index = 0

    def set_position(self, epoch: int, start_index: int) -> None:
        """Make the next iteration read epoch ``epoch`` from its ``start_index``-th item."""
        self.set_epoch(epoch)
        self.start_index = start_index

    def __iter__(self) -> Iterator[int]:
        """Yield this replica's indices of the epoch from ``start_index`` on."""
        indices = list(super().__iter__())
        return iter(indices[self.start_index:])

    def __len__(self) -> int:
        """Return the indices left in this epoch for this replica."""
        return self.num_samples - self.start_index


def collate_clips(items: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """Stack clip items into a batch (B, S, ...) (``sequence_index`` (B,))."""
    return {key: torch.stack([item[key] for item in items]) for key in items[0]}


class ClipLoader:
    """Batches of clips for global steps: step ``s`` reads batch ``s % per_epoch`` of its epoch.

    Attributes:
        dataset: the clips.
        sampler: this process's ``ResumableSampler``.
        batches_per_epoch: full batches per epoch and process.

    """

    def __init__(self, dataset: ClipDataset, batch_size: int, num_workers: int, seed: int,
                 num_replicas: int = 1, rank: int = 0) -> None:
        """Prepare the loader (nothing is read until ``batches``).

        Raises:
            InputError: when there are fewer clips than one batch per process.

        """
        self.dataset = dataset
        self.batch_size = batch_size
        self.num_workers = num_workers
        self.seed = seed
        self.sampler = ResumableSampler(dataset, num_replicas, rank, seed)
        self.batches_per_epoch = self.sampler.num_samples // batch_size
        if self.batches_per_epoch == 0:
            raise InputError(f'training data: {len(dataset)} clips give no batch of '
                             f'{batch_size} per process for {num_replicas} process(es); add '
                             'sequences, lower clip.clip_step or train.batch_size')

    def position(self, step: int) -> tuple[int, int]:
        """Return the (epoch, batch within the epoch) that global step ``step`` reads."""
        return divmod(step, self.batches_per_epoch)

    def batches(self, first_step: int) -> Iterator[dict[str, torch.Tensor]]:
        """Yield the batches of steps ``first_step``, ``first_step + 1``, ... forever."""
        epoch, batch = self.position(first_step)
        while True:
            self.sampler.set_position(epoch, batch * self.batch_size)
            # The loader's own generator (seeded per epoch) keeps the global RNG untouched, so
            # where an iterator starts cannot change the random numbers of training.
            generator = torch.Generator().manual_seed(self.seed + epoch)
            loader = DataLoader(self.dataset, batch_size=self.batch_size,
                                sampler=self.sampler, num_workers=self.num_workers,
                                collate_fn=collate_clips, drop_last=True,
                                generator=generator, persistent_workers=False)
            yield from loader
            epoch, batch = epoch + 1, 0


def build_clip_loader(data: DataConfig, layout: ClipLayout, config: GeometryConfig,
                      batch_size: int, seed: int, num_replicas: int = 1, rank: int = 0,
                      readers: Mapping[str, ReaderFactory] = SAMPLE_READERS) -> ClipLoader:
    """Return the loader of ``data.sequences`` (folders searched for sequences).

    Raises:
        InputError: for missing or unreadable data, or too few clips.

    """
    dataset = ClipDataset(find_sequences(data.sequences), layout, config, readers,
                          data.cache_images)
    return ClipLoader(dataset, batch_size, data.num_workers, seed, num_replicas, rank)
