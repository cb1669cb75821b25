"""The engine's named stages and how they are timed for ``StreamingEngine.stage_timer``.

A stage timer is any callable taking (stage name, seconds); the engine calls it after each
timed stage, from the thread that ran it (the hand source's detection runs in its own thread,
the windowed hands in the decode worker). A child stage's name follows its parent's and a '/'.
The model's own parts are not stages here: time them on ``StreamingEngine.model``.
"""

from collections.abc import Callable
from collections.abc import Iterator
import contextlib
import time
from typing import Final

#: A stage timer: called with (stage name, seconds).
StageTimer = Callable[[str, float], None]

STAGE_PREPARE: Final = 'prepare'  # the stamp, checking and fitting a frame to the model
STAGE_DETECTION: Final = 'hand detection'  # the hand source reading an image (own thread)
STAGE_HANDS: Final = 'hands'  # a block's hands: hand branch, split, hand source
STAGE_SPLIT: Final = 'hands/split into frames'  # per-frame records of a block
STAGE_LIFT: Final = 'hands/hand source'  # the hand source's lifting and gating
STAGE_FINISH: Final = 'finish'  # a record to its result
STAGE_TRACK: Final = 'finish/pose track'  # the pose track (tracker, metric scale)
STAGE_PLACEMENT: Final = 'finish/world placement'  # hands into the world frame
STAGE_OUTPUT: Final = 'finish/output stage'  # identity, shared shape, smoothing
STAGES: Final = (STAGE_PREPARE, STAGE_DETECTION, STAGE_HANDS, STAGE_SPLIT, STAGE_LIFT,
                 STAGE_FINISH, STAGE_TRACK, STAGE_PLACEMENT, STAGE_OUTPUT)


def timed(timer: StageTimer | None, name: str) -> contextlib.AbstractContextManager[None]:
    """Return a context telling ``timer`` how long its body took, as ``name`` (None: nothing)."""
    return contextlib.nullcontext() if timer is None else _timing(timer, name)


@contextlib.contextmanager
def _timing(timer: StageTimer, name: str) -> Iterator[None]:
    """Tell ``timer`` the seconds the body took, as ``name`` (also when it raises)."""
    start = time.perf_counter()
    try:
        yield
    finally:
        timer(name, time.perf_counter() - start)
