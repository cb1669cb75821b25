"""``bag_to_dataset --ray [ADDRESS]``: the same conversion spread over a Ray cluster.

Each input is one task for a converter actor (``shard.ShardConverter``: one engine, loaded once
and kept across its inputs, with ``num_gpus`` when the cluster has GPUs). The actor converts the
whole input, time windows included, into a shard directory inside the dataset root; the driver
adds the finished shards to the dataset in input order (``shard.merge_shard``), so numbering,
statistics and ``meta/`` are exactly the local run's, each episode atomically. Shards are moved
into place, so on a cluster the dataset root must be on storage every node sees. A re-run skips
the episodes already in the dataset. Ray is imported here only, when ``--ray`` is used.
"""

from collections import deque
from collections.abc import Callable
from collections.abc import Iterator
import contextlib
from dataclasses import dataclass
from dataclasses import replace
import logging
from pathlib import Path
from typing import Any

from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.config import RaySettings
from infinihand_ros.convert.dataset_writer import DatasetWriter
from infinihand_ros.convert.inputs import InputSource
from infinihand_ros.convert.report import EpisodeReport
from infinihand_ros.convert.report import FAILED
from infinihand_ros.convert.run import RunOptions
from infinihand_ros.convert.shard import merge_shard
from infinihand_ros.convert.shard import ShardConverter
from infinihand_ros.convert.shard import ShardResult
from infinihand_ros.core.errors import InfiniHandError
from tqdm import tqdm

logger = logging.getLogger(__name__)

RAY_INSTALL_HINT = 'install the version requirements.txt pins (pip install -r requirements.txt)'


class RayStartError(InfiniHandError):
    """Ray is not installed, or the cluster cannot be reached or started."""


@dataclass(frozen=True)
class WorkerPlan:
    """The converter actors of a run: how many, and what each reserves."""

    workers: int
    num_cpus: float
    num_gpus: float


def plan_workers(settings: RaySettings, resources: dict[str, float], inputs: int) -> WorkerPlan:
    """Return the actors for ``inputs`` inputs on a cluster with ``resources`` (CPU, GPU).

    Without ``settings.workers`` there is one actor per ``gpus_per_worker`` GPUs when the
    cluster has GPUs, else one per ``cpus_per_worker`` CPUs; never more than the inputs, at
    least one.
    """
    gpus = float(resources.get('GPU', 0.0))
    num_gpus = settings.gpus_per_worker if gpus > 0 else 0.0
    fitting = (gpus // settings.gpus_per_worker if gpus > 0
               else float(resources.get('CPU', 0.0)) // settings.cpus_per_worker)
    workers = settings.workers or int(fitting)
    return WorkerPlan(max(1, min(workers, inputs)), settings.cpus_per_worker, num_gpus)


def _start_ray(address: str | None, settings: RaySettings) -> tuple[Any, bool]:
    """Return the ``ray`` module, connected when it was not, and whether this call did it."""
    try:
        import ray
    except ImportError as exc:
        raise RayStartError(f'--ray needs Ray, which is not installed: {RAY_INSTALL_HINT}') \
            from exc
    if ray.is_initialized():
        return ray, False
    try:
        ray.init(address=address, include_dashboard=False, configure_logging=False,
                 num_cpus=settings.local_cpus if address is None else None)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        where = address or 'a local Ray instance'
        raise RayStartError(f'--ray: cannot connect to {where} ({exc}); pass the address of a '
                            'running cluster (ray start --head prints it) or no address to '
                            'start a local one') from exc
    return ray, True


def results_in_order(ray: Any, make_actor: Callable[[], Any], workers: int,
                     calls: list[tuple[Any, ...]]) -> Iterator[ShardResult | Exception]:
    """Yield each call's shard (or the Ray error that ended it) in call order.

    Calls run on ``workers`` actors as they become free; an actor that dies is replaced. The
    actors' engines are closed when every call is done, and every actor is killed when the
    generator ends (finished, failed or interrupted).
    """
    queue = deque(enumerate(calls))
    actors = [make_actor() for _ in range(workers)]
    idle = list(actors)
    pending: dict[Any, tuple[int, Any]] = {}
    done: dict[int, ShardResult | Exception] = {}
    next_index = 0
    try:
        while next_index < len(calls):
            while idle and queue:
                index, args = queue.popleft()
                actor = idle.pop()
                pending[actor.convert.remote(*args)] = (index, actor)
            ready, _ = ray.wait(list(pending), num_returns=1)
            index, actor = pending.pop(ready[0])
            try:
                done[index] = ray.get(ready[0])
            except ray.exceptions.RayActorError as exc:
                done[index] = exc
                actor = make_actor()
                actors.append(actor)
            except ray.exceptions.RayError as exc:
                done[index] = exc
            idle.append(actor)
            while next_index in done:
                yield done.pop(next_index)
                next_index += 1
        ray.get([actor.close.remote() for actor in idle])  # every live actor is idle now
    finally:
        for actor in actors:
            ray.kill(actor)


def failure_report(source: InputSource, error: Exception) -> EpisodeReport:
    """Report an input whose worker failed (not a conversion failure: Ray or a crash)."""
    cause = getattr(error, 'cause', None) or error
    reason = f'the Ray worker failed: {type(cause).__name__}: {cause}'.splitlines()[0]
    logger.error('%s: %s', source.path, reason)
    return EpisodeReport(str(source.path), status=FAILED, error=reason)


def convert_on_ray(address: str | None, sources: list[InputSource], config: ConvertConfig,
                   options: RunOptions, writer: DatasetWriter,
                   reports: list[EpisodeReport]) -> None:
    """Convert ``sources`` on Ray into ``writer``'s dataset; append every report to ``reports``.

    Args:
        address: the cluster (``auto``, ``host:6379``, ``ray://host:10001``), or None for
            Ray's lookup (``RAY_ADDRESS``, the cluster last started on this machine) and else
            a new local instance of ``config.ray.local_cpus`` CPUs.
        sources: the inputs, in the order their episodes enter the dataset.
        config: the converter settings (``config.ray`` sizes the actors).
        options: output and input options (workers show no progress bars).
        writer: the dataset; only the driver writes it.
        reports: receives the reports in input order, as the inputs are merged.

    Raises:
        RayStartError: when Ray is missing or the cluster cannot be reached.

    """
    if not sources:
        return
    ray, started = _start_ray(address, config.ray)
    try:
        plan = plan_workers(config.ray, ray.cluster_resources(), len(sources))
        logger.info('converting %d inputs on %d Ray actors', len(sources), plan.workers)
        actor_class = ray.remote(ShardConverter).options(num_cpus=plan.num_cpus,
                                                         num_gpus=plan.num_gpus)
        worker_options = replace(options, progress=False)
        finished = writer.finished_sources()
        with writer.staging() as shards, tqdm(total=len(sources), desc='inputs (ray)',
                                              unit='input', disable=not options.progress) as bar:
            calls = [(source, Path(shards) / f'input-{index:06d}', finished)
                     for index, source in enumerate(sources)]
            results = results_in_order(
                ray, lambda: actor_class.remote(config, worker_options), plan.workers, calls)
            with contextlib.closing(results):
                for index, result in enumerate(results):  # to the end: the engines close
                    if isinstance(result, Exception):
                        reports.append(failure_report(sources[index], result))
                    else:
                        merge_shard(writer, result, reports)
                    bar.update()
    finally:
        if started:
            ray.shutdown()
