"""Which way a frame goes through the engine: the route, decided from the frame's situation.

A pure decision table. The engine gathers the facts (``FrameSituation``) and ``route`` returns
one of four routes: a fixed camera's frame without the model (``STATIC``), the geometry branch
first (``GEOMETRY``, the paper's path), tracked from the image alone between geometry frames
(``TRACKED``), or tracked from the image alone with its geometry branch run after its result
went out (``TRACKED_FIRST``, the deferred geometry of ``engine/deferred_geometry.py``).
"""

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum


class Route(StrEnum):
    """How a checked frame goes on (compares equal to its value)."""

    STATIC = 'static'  # a fixed camera's frame, no model input: the hand source only
    GEOMETRY = 'geometry'  # the geometry branch first (held back into blocks as needed)
    TRACKED = 'tracked'  # tracked from the image alone; enters no streaming memory
    TRACKED_FIRST = 'tracked_first'  # tracked first; its geometry branch runs afterwards


@dataclass(frozen=True)
class FrameSituation:
    """The facts that decide a frame's route.

    Attributes:
        fitted: the frame was fitted to the model input (False: a fixed camera's frame that
            needs no model, ``STATIC``).
        per_frame: the engine runs in per-frame mode (not windowed).
        geometry_interval: the geometry branch runs on every this-many-th frame (``engine``
            config; 1: every frame).
        tracking: a moving camera whose images are tracked (the tracker is enabled).
        hand_branch: the hands come from the model's hand branch (it needs the geometry).
        held_back: frames are held back for the next block (frames never overtake them).
        in_anchors: the frame is one of the stream's anchor frames.
        frames_since_geometry: frames since the last frame whose geometry the pose track has
            (or, while one is owed, since the owed frame); None before the first.
        owed: a frame's geometry branch is still owed (``geometry_lag`` >= 1).
        owed_failed: the last owed geometry branch failed, and none has succeeded since.
        tracker_needs_depth: the tracker needs a depth (a new reference, or a restart).
        tracker_lost: the tracker lost the camera (its prior is the network's pose).
        scale_warmup: the metric scale still warms up (frames with hands give samples).
        bundle_adjustment: a BA backend takes keyframes (they carry their depth at once).

    """

    fitted: bool
    per_frame: bool
    geometry_interval: int
    tracking: bool
    hand_branch: bool
    held_back: bool
    in_anchors: bool
    frames_since_geometry: int | None
    owed: bool
    owed_failed: bool
    tracker_needs_depth: bool
    tracker_lost: bool
    scale_warmup: bool
    bundle_adjustment: bool


def route(situation: FrameSituation, has_hands: Callable[[], bool]) -> Route:
    """Return how a frame in ``situation`` goes on.

    ``TRACKED`` and ``TRACKED_FIRST`` only in per-frame mode for a tracked moving camera whose
    hands come from outside the model (``geometry_interval`` > 1), after the anchors, once a
    geometry frame was seen. A frame where the tracker needs depth runs the geometry branch:
    first when the tracker lost the camera (its network pose is the prior), after its result
    for a new reference; so does a frame with hands while the metric scale warms up (its depth
    gives the samples); with BA it always comes first (its keyframes carry their depth). A
    frame after one whose geometry is still owed is ``TRACKED`` (the owed one brings the depth
    it would need).

    Args:
        situation: the frame's facts.
        has_hands: whether the hand source found hands in the frame; called only where it
            decides the route (it waits for the frame's detection, which otherwise runs
            beside the model).

    """
    if not situation.fitted:
        return Route.STATIC
    since = situation.frames_since_geometry
    if (situation.geometry_interval == 1 or not situation.per_frame or not situation.tracking
            or situation.hand_branch or situation.held_back or situation.in_anchors
            or since is None or situation.owed_failed
            or (situation.tracker_needs_depth and situation.tracker_lost)):
        return Route.GEOMETRY
    if (since < situation.geometry_interval
            and not (situation.tracker_needs_depth and not situation.owed)
            and not (situation.scale_warmup and has_hands())):
        return Route.TRACKED
    return Route.GEOMETRY if situation.bundle_adjustment else Route.TRACKED_FIRST
