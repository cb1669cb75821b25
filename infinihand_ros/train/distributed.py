"""Multi-process training through the standard launcher: ``torchrun`` + DistributedDataParallel.

Under ``torchrun`` (which sets ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK`` and the rendezvous
address) ``init_distributed`` joins the process group (NCCL on CUDA, gloo on the CPU); a plain
``python``/``train`` start is one process and needs no group. Only rank 0 writes logs and
checkpoints; ``gather_objects`` and ``mean_values`` collect what it writes from every rank, and
``replica_checksum`` lets a run confirm that its replicas hold the same weights.
"""

from dataclasses import dataclass
import datetime
import gc
import os
import time
from typing import Any

from infinihand_ros.core.errors import ConfigError
import torch
from torch import nn
import torch.distributed as dist

#: How long ranks wait for each other before a collective fails.
_TIMEOUT = datetime.timedelta(minutes=30)
#: Seconds the gloo threads get, without the GIL, to free finished work before teardown.
GLOO_SETTLE_S = 0.2


@dataclass(frozen=True)
class DistributedContext:
    """Where this process stands in the run.

    Attributes:
        rank: global rank (0 when not distributed).
        world_size: number of processes (1 when not distributed).
        local_rank: rank on this machine (its CUDA device index).
        enabled: a process group was initialised (``torchrun`` with more than one process).

    """

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    enabled: bool = False

    @property
    def is_main(self) -> bool:
        """Return True on the process that writes logs and checkpoints."""
        return self.rank == 0


def _env_int(name: str, default: int) -> int:
    """Return integer environment variable ``name`` (ConfigError when not an integer)."""
    text = os.environ.get(name)
    if text is None:
        return default
    try:
        return int(text)
    except ValueError as exc:
        raise ConfigError(f'environment {name}={text!r} (set by torchrun) is not an '
                          'integer') from exc


def init_distributed(use_cuda: bool) -> DistributedContext:
    """Join the torchrun process group when launched by torchrun with WORLD_SIZE > 1.

    Args:
        use_cuda: the run trains on CUDA (NCCL backend, one device per local rank).

    """
    world_size = _env_int('WORLD_SIZE', 1)
    if world_size <= 1:
        return DistributedContext()
    rank, local_rank = _env_int('RANK', 0), _env_int('LOCAL_RANK', 0)
    if use_cuda:
        torch.cuda.set_device(local_rank)
    if not dist.is_initialized():
        dist.init_process_group('nccl' if use_cuda else 'gloo', timeout=_TIMEOUT)
    return DistributedContext(rank, world_size, local_rank, True)


def shutdown_distributed(context: DistributedContext) -> None:
    """Leave the process group (no-op when not distributed).

    Gloo's worker threads free finished collectives' Python-side tensors, which needs the GIL;
    a process group destroyed by a thread that holds the GIL meanwhile deadlocks (seen at the
    end of a 2-process CPU run: ``~ProcessGroupGloo`` in the main thread, a gloo thread in
    ``~AsyncAllgatherWork`` waiting for the GIL). So the caller drops its DDP wrapper first
    and the gloo threads get a moment without the GIL before the group goes.
    """
    if context.enabled and dist.is_initialized():
        gc.collect()
        time.sleep(GLOO_SETTLE_S)  # releases the GIL
        dist.destroy_process_group()


def gather_objects(context: DistributedContext, value: Any) -> list[Any]:
    """Return every rank's ``value`` by rank (``[value]`` when not distributed)."""
    if not context.enabled:
        return [value]
    gathered: list[Any] = [None] * context.world_size
    dist.all_gather_object(gathered, value)
    return gathered


def mean_values(context: DistributedContext, values: dict[str, torch.Tensor],
                device: torch.device) -> dict[str, float]:
    """Return each scalar averaged over the ranks, as floats (same keys on every rank)."""
    names = list(values)
    stacked = torch.stack([values[name].detach().double().reshape(()) for name in names])
    stacked = stacked.to(device)
    if context.enabled:
        dist.all_reduce(stacked)
        stacked /= context.world_size
    return dict(zip(names, stacked.cpu().tolist()))


def barrier(context: DistributedContext) -> None:
    """Wait for every rank (no-op when not distributed)."""
    if context.enabled:
        dist.barrier()


@torch.no_grad()
def replica_checksum(model: nn.Module) -> float:
    """Return a float64 checksum of the parameters (it changes with any value or the order)."""
    total = torch.zeros((), dtype=torch.float64)
    for index, parameter in enumerate(model.parameters()):
        total += (index + 1) * parameter.detach().double().sum().cpu()
    return float(total)
