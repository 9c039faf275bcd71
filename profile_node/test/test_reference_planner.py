import numpy as np
import pytest

from ato_common.scenario import load_scenario
from profile_node.planner import plan_reference
from profile_node.trajectory import TrajectoryBuilder, speed_change_distance


@pytest.fixture(scope='module')
def plan():
    return plan_reference(load_scenario('short_line'))


def sample(plan, dt=0.05):
    t = np.arange(0.0, plan.trajectory.end_time + 5.0, dt)
    points = [plan.trajectory.at(x) for x in t]
    return (t, np.array([p.position for p in points]), np.array([p.speed for p in points]),
            np.array([p.acceleration for p in points]))


def test_speed_is_the_derivative_of_position_and_acceleration_of_speed(plan):
    t, x, v, a = sample(plan, 0.01)
    dx = np.gradient(x, t)
    dv = np.gradient(v, t)
    assert np.max(np.abs(dx - v)[1:-1]) < 1e-3
    assert np.max(np.abs(dv - a)[1:-1]) < 2e-3


def test_never_above_the_permitted_speed_and_never_backwards(plan):
    scenario = load_scenario('short_line')
    t, x, v, a = sample(plan)
    limits = np.array([scenario.line.speed_limit_mps(p) for p in x])
    assert np.all(v <= limits - scenario.planning.speed_margin_mps + 1e-9)
    assert np.all(v >= -1e-12)
    assert np.all(np.diff(x) >= -1e-9)


def test_acceleration_and_jerk_within_the_planning_limits(plan):
    p = load_scenario('short_line').planning
    t, x, v, a = sample(plan)
    assert np.max(a) <= p.max_acceleration_mps2 + 1e-9
    assert np.min(a) >= -p.service_deceleration_mps2 - 1e-9
    jerks = [abs(s.jerk) for s in plan.trajectory.segments]
    assert max(jerks) <= p.max_jerk_mps3 + 1e-12


def test_stops_exactly_at_each_station_and_stands_still_while_dwelling(plan):
    for stop in plan.stops:
        for t in np.linspace(stop.arrival_s, stop.departure_s, 7):
            point = plan.trajectory.at(t)
            assert point.position == pytest.approx(stop.station.position_m, abs=0.01)
            assert point.speed == pytest.approx(0.0, abs=1e-9)
    assert plan.stops[-1].station.name == 'Terminus'
    assert plan.trajectory.at(plan.trajectory.end_time + 100).speed == 0.0


def test_next_stop_and_distance_to_go(plan):
    first, second = plan.stops
    assert plan.next_stop(0.0) is first
    assert plan.next_stop(first.arrival_s + 1.0) is first       # dwelling
    assert plan.next_stop(first.departure_s + 1.0) is second
    assert plan.next_stop(1e9) is second


def end_of_segments(builder):
    last = builder.segments[-1]
    return last.at(last.t0 + last.duration)


def test_s_curve_speed_change_distance_is_exact():
    builder = TrajectoryBuilder()
    builder.speed_change(50.0, 0.5, 0.2)
    x, v, a = end_of_segments(builder)
    assert x == pytest.approx(speed_change_distance(0.0, 50.0, 0.5, 0.2), rel=1e-12)
    assert v == pytest.approx(50.0, abs=1e-9) and a == pytest.approx(0.0, abs=1e-12)
    short = TrajectoryBuilder()
    short.speed_change(0.5, 0.5, 0.2)  # too small to reach the acceleration limit
    assert max(abs(s.a0) for s in short.segments) < 0.5


@pytest.mark.parametrize('target', [0.001, 0.004, 0.02, 0.05, 0.08, 0.12, 0.5, 3.0, 30.0, 80.0])
def test_traction_phase_ends_exactly_at_any_target_speed(target):
    jerk = 0.1
    builder = TrajectoryBuilder()
    builder.accelerate_to(target, lambda v: 0.4 - 0.003 * v, jerk, 0.02)
    x, v, a = end_of_segments(builder)
    assert v == pytest.approx(target, rel=1e-9, abs=1e-9)
    assert a == pytest.approx(0.0, abs=1e-9)
    assert max(abs(s.jerk) for s in builder.segments) <= jerk + 1e-12
    assert max(s.a0 for s in builder.segments) <= 0.4 + 1e-9
