"""What a bundle-adjustment worker reports: its state and counters (``worker.statistics``)."""

from dataclasses import dataclass
from enum import StrEnum


class WorkerState(StrEnum):
    """What a ``BundleAdjustmentWorker`` is doing (compares equal to its string value)."""

    IDLE = 'idle'  # ready, nothing queued or running
    RUNNING = 'running'  # a call is running or queued
    STOPPED = 'stopped'  # closed: no more calls
    FAILED = 'failed'  # cannot run calls any more (see ``last_error``); create a new worker


@dataclass(frozen=True)
class WorkerStatistics:
    """A consistent snapshot of a worker's counters.

    After ``close()``, ``submitted == done + failed + dropped``.

    Attributes:
        state: what the worker is doing.
        submitted: requests and selections accepted by ``submit``/``submit_selection``.
        done: calls that gave a result.
        dropped: queued selections dropped because the worker was behind (or closed early).
        failed: calls that gave no result (the error is logged; poses stay uncorrected).
        rejected: calls done whose refinement failed its held-out check (their start stood).
        callback_errors: results whose callback raised (the result still counts as done).
        process_starts: BA processes started (more than one: a process died and was replaced).
        last_error: the last failure's message (a call, the BA process or a callback), or None.

    """

    state: WorkerState
    submitted: int
    done: int
    dropped: int
    failed: int
    rejected: int
    callback_errors: int
    process_starts: int
    last_error: str | None
