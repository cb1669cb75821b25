"""The geometry interval chosen from measured cost (``engine/pacing.py``)."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.pacing import choose_interval
from infinihand_ros.engine.pacing import MIN_SAMPLES
from infinihand_ros.engine.pacing import Pacer
from infinihand_ros.engine.pacing import PacingConfig
from infinihand_ros.engine.pacing import START_INTERVAL
import pytest

CONFIG = PacingConfig(utilisation=0.7, relax=0.85, max_geometry_interval=8)
NS = 1_000_000_000


def test_smallest_interval_within_the_budget():
    # 10 Hz, 70 %: 70 ms a frame. A tracked frame 40 ms leaves 30 ms for 200 ms of geometry.
    assert choose_interval(0.040, 0.200, 0.1, 3, CONFIG) == 7
    assert 0.040 + 0.200 / 7 <= 0.07 < 0.040 + 0.200 / 6


def test_a_fast_machine_runs_the_geometry_branch_on_every_frame():
    assert choose_interval(0.005, 0.020, 0.1, 3, CONFIG) == 1


def test_no_interval_fits_takes_the_largest():
    assert choose_interval(0.080, 0.200, 0.1, 3, CONFIG) == 8


def test_going_down_needs_the_margin():
    # 7 fits the budget (68.6 ms <= 70) but not 85 % of it: the engine stays at 8.
    assert choose_interval(0.040, 0.200, 0.1, 8, CONFIG) == 8
    # Costs halved: 3 fits within the margin (43 ms <= 59.5).
    assert choose_interval(0.010, 0.100, 0.1, 8, CONFIG) == 3


def _paced(frame_s: float, geometry_s: float, period_ns: int, frames: int) -> Pacer:
    pacer = Pacer('auto', 2, CONFIG, applies=True)
    for index in range(frames):
        pacer.pushed(index * period_ns)
        pacer.frame_cost(frame_s)
        pacer.geometry_cost(geometry_s)
    return pacer


def test_pacer_starts_at_the_start_interval_until_it_has_measured():
    pacer = _paced(0.040, 0.200, NS // 10, MIN_SAMPLES - 1)
    assert pacer.interval == START_INTERVAL
    state = pacer.state()
    assert state.paced and state.geometry_interval == START_INTERVAL
    assert state.frame_ms == pytest.approx(40.0) and state.period_ms == pytest.approx(100.0)


def test_pacer_follows_the_costs_and_holds_the_lag_below_the_interval():
    pacer = _paced(0.040, 0.200, NS // 10, 10)
    assert pacer.interval == 7 and pacer.lag == 2
    state = pacer.state()
    assert state.utilisation == pytest.approx((0.040 + 0.200 / 7) / 0.1)
    fast = _paced(0.010, 0.030, NS // 10, 10)
    assert fast.interval == 1 and fast.lag == 0


def test_arrivals_give_the_period_when_a_caller_drops_frames():
    pacer = Pacer('auto', 2, CONFIG, applies=True)
    for index in range(12):
        pacer.arrived(index * NS // 10)  # 10 Hz in
        if index % 2 == 0:
            pacer.pushed(index * NS // 10)  # every other frame pushed
    assert pacer.state().period_ms == pytest.approx(100.0)


def test_a_fixed_interval_is_never_changed():
    pacer = Pacer(5, 2, CONFIG, applies=True)
    for index in range(10):
        pacer.pushed(index * NS // 10)
        pacer.frame_cost(0.001)
        pacer.geometry_cost(0.001)
    assert not pacer.paced and pacer.interval == 5


def test_engine_config_takes_auto_or_a_number():
    assert EngineConfig().geometry_interval == 'auto'
    assert EngineConfig(geometry_interval=4, geometry_lag=2).geometry_interval == 4
    with pytest.raises(ConfigError, match='geometry_interval'):
        EngineConfig(geometry_interval='often')
    with pytest.raises(ConfigError, match='geometry_interval'):
        EngineConfig(geometry_interval=0)
    with pytest.raises(ConfigError, match='utilisation'):
        PacingConfig(utilisation=1.5)
