"""Tests of engine/schedule.py: the route of a frame from its situation (the decision table)."""

from dataclasses import replace

from infinihand_ros.engine.schedule import FrameSituation
from infinihand_ros.engine.schedule import Route
from infinihand_ros.engine.schedule import route
import pytest

#: A moving camera, hands from outside the model, every 3rd frame a geometry frame, the frame
#: right after one: tracked from the image alone.
BETWEEN = FrameSituation(fitted=True, per_frame=True, geometry_interval=3, tracking=True,
                         hand_branch=False, held_back=False, in_anchors=False,
                         frames_since_geometry=1, owed=False, owed_failed=False,
                         tracker_needs_depth=False, tracker_lost=False, scale_warmup=False,
                         bundle_adjustment=False)


def _no_hands() -> bool:
    return False


def _hands() -> bool:
    return True


def test_a_frame_between_geometry_frames_is_tracked() -> None:
    assert route(BETWEEN, _no_hands) is Route.TRACKED
    assert route(replace(BETWEEN, frames_since_geometry=2), _no_hands) is Route.TRACKED


def test_a_frame_without_model_input_is_static_whatever_else_holds() -> None:
    """A fixed camera's frame that was not fitted goes on without the model."""
    for situation in (BETWEEN, replace(BETWEEN, geometry_interval=1, in_anchors=True)):
        assert route(replace(situation, fitted=False), _hands) is Route.STATIC


@pytest.mark.parametrize('fact', [
    {'geometry_interval': 1},  # the reference path: geometry on every frame
    {'per_frame': False},  # windowed mode
    {'tracking': False},  # a fixed camera, or the tracker off
    {'hand_branch': True},  # the hand branch needs the geometry
    {'held_back': True},  # frames never overtake held-back ones
    {'in_anchors': True},
    {'frames_since_geometry': None},  # no geometry frame seen yet
    {'owed_failed': True},  # the owed geometry failed: geometry first until one succeeds
    {'tracker_needs_depth': True, 'tracker_lost': True},  # the network's pose is the prior
])
def test_these_facts_put_the_geometry_branch_first(fact: dict) -> None:
    assert route(replace(BETWEEN, **fact), _no_hands) is Route.GEOMETRY
    assert route(replace(BETWEEN, bundle_adjustment=True, **fact), _no_hands) is Route.GEOMETRY


@pytest.mark.parametrize('fact', [
    {'frames_since_geometry': 3},  # the geometry_interval-th frame
    {'frames_since_geometry': 7},
    {'tracker_needs_depth': True},  # a new reference (not lost): its depth after the answer
])
def test_a_geometry_frame_goes_out_first_without_ba_and_after_its_geometry_with_it(
        fact: dict) -> None:
    assert route(replace(BETWEEN, **fact), _no_hands) is Route.TRACKED_FIRST
    assert route(replace(BETWEEN, bundle_adjustment=True, **fact), _no_hands) is Route.GEOMETRY


def test_while_geometry_is_owed_a_frame_needing_depth_is_tracked() -> None:
    """The owed frame brings the depth the tracker waits for."""
    owed = replace(BETWEEN, owed=True, tracker_needs_depth=True)
    assert route(owed, _no_hands) is Route.TRACKED
    assert route(replace(owed, frames_since_geometry=3), _no_hands) is Route.TRACKED_FIRST


def test_a_lost_tracker_that_needs_no_depth_keeps_tracking() -> None:
    assert route(replace(BETWEEN, tracker_lost=True), _no_hands) is Route.TRACKED


def test_hands_while_the_scale_warms_up_bring_the_geometry() -> None:
    """Their depth gives the metric scale's samples; without hands the frame is tracked."""
    warmup = replace(BETWEEN, scale_warmup=True)
    assert route(warmup, _hands) is Route.TRACKED_FIRST
    assert route(warmup, _no_hands) is Route.TRACKED
    assert route(replace(warmup, bundle_adjustment=True), _hands) is Route.GEOMETRY
    assert route(BETWEEN, _hands) is Route.TRACKED  # after the warm-up hands change nothing


def test_the_hands_are_asked_for_only_where_they_decide() -> None:
    """Asking waits for the frame's detection, which otherwise runs beside the model."""
    asked = []

    def hands() -> bool:
        asked.append(True)
        return True

    for situation in (BETWEEN, replace(BETWEEN, fitted=False),
                      replace(BETWEEN, geometry_interval=1, scale_warmup=True),
                      replace(BETWEEN, frames_since_geometry=3, scale_warmup=True),
                      replace(BETWEEN, tracker_needs_depth=True, scale_warmup=True)):
        route(situation, hands)
    assert not asked
    route(replace(BETWEEN, scale_warmup=True), hands)
    assert len(asked) == 1


def test_routes_compare_equal_to_their_names() -> None:
    assert [str(way) for way in Route] == ['static', 'geometry', 'tracked', 'tracked_first']
