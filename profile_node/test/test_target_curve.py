"""The target curve of every built-in scenario: under the permitted speed, exact stops, limits,
consistent derivatives; limit changes inside a leg; the jinan_xuzhou figures."""

from dataclasses import replace

import numpy as np
import pytest

from ato_common import units
from ato_common.scenario import builtin_scenarios, load_scenario, parse_scenario
from profile_node.planner import PlanningError, plan_reference

PRESETS = ['jinan_xuzhou', 'liu_li_2020', 'mao_2017_modes', 'mao_4car', 'luo_xu_crh3']


@pytest.fixture(scope='module', params=sorted(builtin_scenarios()))
def planned(request):
    scenario = load_scenario(request.param)
    return scenario, plan_reference(scenario)


def test_every_preset_of_the_papers_is_built_in():
    assert set(PRESETS) <= set(builtin_scenarios())


def samples(plan, step_s):
    t = np.arange(0.0, plan.trajectory.end_time + 2.0, step_s)
    points = [plan.trajectory.at(x) for x in t]
    return t, points


def test_target_never_exceeds_the_permitted_speed_nor_the_static_limit(planned):
    scenario, plan = planned
    # Offset from the planner's own check grid, so this is an independent sampling.
    t, points = samples(plan, 0.37)
    margin = scenario.planning.speed_margin_mps
    for time_s, p in zip(t, points):
        permitted = plan.permitted_speed(p.position, time_s)
        assert p.speed <= permitted + 1e-6, (time_s, p.position)
        assert p.speed <= scenario.line.speed_limit_mps(p.position) - margin + 1e-9
    assert min(p.speed for p in points) >= -1e-9


def test_stops_exactly_at_every_station_and_stands_still_while_dwelling(planned):
    scenario, plan = planned
    stations = [s for s in scenario.line.stations
                if s.position_m > scenario.run.initial_position_m]
    assert [s.station for s in plan.stops] == stations
    for stop in plan.stops:
        for time_s in np.linspace(stop.arrival_s, stop.departure_s, 5):
            point = plan.trajectory.at(time_s)
            assert point.position == pytest.approx(stop.station.position_m, abs=0.01)
            assert point.speed == pytest.approx(0.0, abs=1e-9)
        # the last approach ends at the station, it never passes it
        before = plan.trajectory.at(stop.arrival_s - 1.0)
        assert before.position < stop.station.position_m + 0.01


def test_acceleration_and_jerk_within_the_planning_limits(planned):
    scenario, plan = planned
    p = scenario.planning
    segments = plan.trajectory.segments
    starts = np.array([s.a0 for s in segments])
    ends = np.array([s.a0 + s.jerk * s.duration for s in segments])
    # a is linear on each segment, so its extremes are at the segment ends.
    assert max(starts.max(), ends.max()) <= p.max_acceleration_mps2 + 1e-9
    assert min(starts.min(), ends.min()) >= -p.service_deceleration_mps2 - 1e-9
    assert max(abs(s.jerk) for s in segments) <= p.max_jerk_mps3 + 1e-12


def test_position_speed_acceleration_and_jerk_are_consistent(planned):
    scenario, plan = planned
    t = np.arange(0.0, min(plan.trajectory.end_time, 1500.0), 0.01)
    points = [plan.trajectory.at(x) for x in t]
    x = np.array([p.position for p in points])
    v = np.array([p.speed for p in points])
    a = np.array([p.acceleration for p in points])
    # Central differences of a piecewise cubic: exact up to h^2 x'''' terms, and x'''' is zero
    # inside a segment; at a segment boundary the error is bounded by the jerk step h/2.
    h = t[1] - t[0]
    jerk = scenario.planning.max_jerk_mps3
    assert np.max(np.abs((x[2:] - x[:-2]) / (2 * h) - v[1:-1])) < 1e-6 + jerk * h * h
    assert np.max(np.abs((v[2:] - v[:-2]) / (2 * h) - a[1:-1])) < 1e-6 + jerk * h
    # the reported jerk is the derivative of the acceleration wherever a segment holds it
    j = np.array([p.jerk for p in points])
    da = (a[1:] - a[:-1]) / h
    inside = np.abs(j[1:] - j[:-1]) < 1e-12
    assert np.max(np.abs(da[inside] - j[:-1][inside])) < 1e-6
    # continuity: no jump of x, v or a anywhere
    assert np.max(np.abs(np.diff(a))) <= jerk * h + 1e-9


def test_distance_to_go_names_the_next_target(planned):
    scenario, plan = planned
    for stop in plan.stops:
        dwelling = plan.next_target(stop.station.position_m, 0.5 * (stop.arrival_s
                                                                     + stop.departure_s))
        assert dwelling.location_m == stop.station.position_m
    t, points = samples(plan, 5.0)
    for time_s, p in zip(t, points):
        target = plan.next_target(p.position, time_s)
        assert target.location_m >= p.position - 0.01
        # the target is always reached at or below its speed
        if target.kind == 'speed_decrease':
            arrival = next(q for q in points if q.position >= target.location_m)
            assert arrival.speed <= target.speed_mps + 1e-9


def test_the_next_target_is_the_first_ahead_of_a_scan_of_every_target(planned):
    """The target the profile's distance to go is measured to is, at every tick, the first speed
    decrease ahead before the next stop's station, else that stop's own target, as a scan of
    every target of the run finds them (the plan looks them up per stop)."""
    scenario, plan = planned
    t, points = samples(plan, 1.3)
    for time_s, p in zip(t, points):
        stop_index = next((i for i, stop in enumerate(plan.stops) if time_s < stop.departure_s),
                          len(plan.stops) - 1)
        station_m = plan.stops[stop_index].station.position_m
        target = next((x for x in plan.targets if x.kind == 'speed_decrease'
                       and p.position < x.location_m < station_m), None) or next(
            x for x in plan.targets if x.kind != 'speed_decrease' and x.location_m == station_m)
        assert plan.next_target(p.position, time_s) is target, time_s


def test_a_speed_decrease_is_the_next_target_until_it_is_passed():
    plan = plan_reference(load_scenario('mao_4car'))  # a speed decrease before each stop
    decreases = [x for x in plan.targets if x.kind == 'speed_decrease']
    assert len(decreases) == 2
    for decrease in decreases:
        time_s = next(p.time_s for p in samples(plan, 0.5)[1]
                      if p.position >= decrease.location_m - 100.0)
        assert plan.next_target(decrease.location_m - 1.0, time_s) is decrease
        assert plan.next_target(decrease.location_m, time_s) is not decrease


def test_a_plan_without_a_target_at_a_stop_names_the_stop():
    plan = plan_reference(load_scenario('short_line'))
    broken = replace(plan, targets=tuple(t for t in plan.targets if t.kind == 'speed_decrease'))
    with pytest.raises(ValueError, match=f'no target at the stop {plan.stops[0].station.name}'):
        broken.next_target(0.0, 0.0)


def test_jinan_xuzhou_covers_228_km_in_3160_s_at_up_to_310_kmh():
    scenario = load_scenario('jinan_xuzhou')
    plan = plan_reference(scenario)
    trajectory = plan.trajectory
    assert trajectory.end_position - trajectory.at(0.0).position == \
        pytest.approx(228_000.0, rel=0.02)
    assert plan.stops[-1].arrival_s == pytest.approx(3160.0, rel=0.02)
    top = max(trajectory.at(t).speed for t in np.arange(0.0, trajectory.end_time, 1.0))
    assert units.mps_to_kmh(top) == pytest.approx(310.0, abs=0.01)
    # the 12 per mille region is part of the line
    assert max(scenario.line.grade_sine.values) == pytest.approx(units.per_mille_to_sine(12.0))


def test_mao_2017_run_accelerates_to_400_s_cruises_and_brakes_from_1400_s_to_a_stop():
    plan = plan_reference(load_scenario('mao_2017_modes'))
    t = np.arange(0.0, plan.trajectory.end_time, 0.5)
    a = np.array([plan.trajectory.at(x).acceleration for x in t])
    assert t[a > 1e-9][-1] == pytest.approx(400.0, abs=10.0)
    assert t[a < -1e-9][0] == pytest.approx(1400.0, abs=10.0)
    assert plan.stops[-1].arrival_s == pytest.approx(2000.0, abs=20.0)


def one_leg(limits, train='crh3_luo_xu', length=30000.0, **planning):
    return parse_scenario({
        'name': 'leg', 'train': {'preset': train},
        'line': {'name': 'leg', 'length_m': length,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': length}],
                 'speed_limits': [{'start_m': s, 'speed_kmh': v} for s, v in limits]},
        'planning': {'max_acceleration_mps2': 0.4, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.1, 'speed_margin_kmh': 5, **planning}})


def first_time(plan, condition, step=0.1):
    for t in np.arange(0.0, plan.trajectory.end_time, step):
        if condition(plan.trajectory.at(t)):
            return plan.trajectory.at(t)
    return None


def test_a_lower_limit_inside_a_leg_is_reached_at_its_start_and_left_after_the_train():
    scenario = one_leg([(0, 250), (12000, 160), (16000, 250)])
    plan = plan_reference(scenario)
    low = units.kmh_to_mps(160 - 5)
    at_drop = first_time(plan, lambda p: p.position >= 12000.0)
    assert at_drop.speed <= low + 1e-9
    # it cruised faster before (the curve uses the limit, not the leg's lowest)
    before = [plan.trajectory.at(t) for t in range(0, 400)]
    assert max(p.speed for p in before if p.position < 12000.0) > units.kmh_to_mps(200)
    # no acceleration until the whole train (200 m) has left the lower limit
    rising = first_time(plan, lambda p: p.position > 12000.0 and p.acceleration > 1e-9)
    assert rising.position >= 16000.0 + scenario.train.length_m - 1.0
    assert first_time(plan, lambda p: p.position > 17000.0).speed > low + 1.0


def test_the_braking_to_a_lower_limit_starts_no_later_than_the_permitted_curve_demands():
    scenario = one_leg([(0, 250), (12000, 160), (16000, 250)])
    plan = plan_reference(scenario)
    supervision = plan.supervision.legs[0]
    target = next(t for t in supervision.targets if t.kind == 'speed_decrease')
    assert target.location_m == 12000.0
    # the permitted curve comes down to 160 km/h before the limit starts, by the service
    # brake build-up and driver reaction times at that speed
    ahead = 160 / 3.6 * (scenario.supervision.service_brake_build_up_s
                         + scenario.supervision.driver_reaction_s)
    assert supervision.permitted_speed(12000.0 - ahead + 1.0) == pytest.approx(160 / 3.6,
                                                                               abs=0.05)
    assert supervision.permitted_speed(12000.0 - ahead - 200.0) > 160 / 3.6 + 1.0


def test_a_train_that_cannot_start_is_a_planning_error_naming_the_place():
    scenario = parse_scenario({
        'name': 'steep', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'steep', 'length_m': 10000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 10000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 200}],
                 'gradients': [{'start_m': 0, 'per_mille': 60}]},
        'planning': {'max_acceleration_mps2': 0.4, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.1}})
    with pytest.raises(PlanningError, match=r'line at 0-\d+ m: the train cannot start'):
        plan_reference(scenario)
