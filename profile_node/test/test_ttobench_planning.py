"""The planner on TTOBench tracks, trains and journeys: every sample track gives a curve within
its limits that serves its stops; a journey's timetable holds departures and reports its windows.
(The TTOBench reader itself is tested in ato_common/test/test_ttobench.py.)"""

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from ato_common.scenario import load_scenario, parse_scenario
from ato_common.ttobench import load_train, scenario_data
from profile_node.planner import PlanningError, plan_reference

# The BSD-2 TTOBench samples ship with the tests (tests/data/ttobench, with their licence).
SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
TRACKS = sorted((SAMPLES / 'tracks').glob('*.json'))
TRAINS = sorted((SAMPLES / 'trains').glob('*.json'))
assert TRACKS and TRAINS, f'the TTOBench samples are missing from {SAMPLES}'

# A synthetic track and journey (tests/data/synthetic) for what the samples do not cover.
SYNTHETIC = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'synthetic'
TRACK = json.loads((SYNTHETIC / 'ttobench_track_T_curvy.json').read_text())

JOURNEY = json.loads((SYNTHETIC / 'ttobench_journey_T_curvy_J1.json').read_text())


def write(tmp_path, name, data):
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def load_scenario_file(tmp_path, overrides):
    data = {'name': 'tto', 'train': {'preset': 'crh3_luo_xu'},
            'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                         'max_jerk_mps3': 0.3}}
    data.update(overrides)
    path = tmp_path / 'scenario.yaml'
    path.write_text(yaml.safe_dump(data))
    return load_scenario(str(path))


def test_every_sample_track_loads_and_yields_a_curve_within_its_limits_and_stops(tmp_path):
    assert len(TRACKS) >= 14 and len(TRAINS) >= 3
    for i, track in enumerate(TRACKS):
        train = TRAINS[i % len(TRAINS)]   # every track, every train at least once
        scenario = parse_scenario(scenario_data(track, train, dwell_s=20.0))
        raw = json.loads(track.read_text())
        stops = raw['stops']['values']
        assert [s.position_m for s in scenario.line.stations] == stops
        plan = plan_reference(scenario)
        assert [s.station.position_m for s in plan.stops] == stops[1:]
        for stop in plan.stops:
            at = plan.trajectory.at(stop.arrival_s)
            assert at.position == pytest.approx(stop.station.position_m, abs=0.01), track.name
            assert at.speed == pytest.approx(0.0, abs=1e-9)
        limits = raw['speed limits']['values']
        top = load_train(train).max_speed_mps
        for t in np.arange(0.0, plan.trajectory.end_time, 1.3):
            p = plan.trajectory.at(t)
            static = [v for s, v in limits if s <= p.position][-1] / 3.6
            assert p.speed <= min(static, top) + 1e-9, (track.name, p)
            assert p.speed <= plan.permitted_speed(p.position, t) + 1e-6


def test_a_journey_timetable_holds_departures_and_reports_its_windows(tmp_path):
    write(tmp_path, 'track.json', TRACK)
    journey = copy.deepcopy(JOURNEY)
    journey['timing points']['values'] = [[0, 0, 0, 0, 0], [3500, None, None, 10, 60],
                                          [6000, 300, 330, 0, 0], [6000, 600, None, 0, 0],
                                          [12000, 650, 700, 0, 0]]
    write(tmp_path, 'journey.json', journey)
    given = {'line': {'ttobench': 'track.json'}, 'journey': {'ttobench': 'journey.json'}}
    # The journey gives times: the timetable strategy by default, which refuses windows that
    # cannot all be met, naming them and the shortest running time between them.
    scenario = load_scenario_file(tmp_path, given)
    assert scenario.timetable.strategy == 'timetable'
    with pytest.raises(PlanningError) as refused:
        plan_reference(scenario)
    message = str(refused.value)
    assert ('timing point 4 (stop at 12000 m, window [650, 700] s) cannot be reached from '
            'timing point 3 (stop at 6000 m, window [600, -] s) in time: the shortest running '
            'time between them is 23') in message
    assert 'the windows leave 100.0 s' in message and 'timetable.run_infeasible' in message
    # The flag runs it anyway, as close as possible: the fastest where a window is missed
    # (the least-energy curve at the price of time where no coast pays: within half a second
    # of the fastest strategy's curve, which switches at other places under the jerk limit).
    anyway = plan_reference(load_scenario_file(tmp_path, {
        **given, 'timetable': {'run_infeasible': True}}))
    fastest = plan_reference(load_scenario_file(tmp_path, {
        **given, 'timetable': {'strategy': 'fastest'}}))
    assert anyway.stops[-1].arrival_s == pytest.approx(fastest.stops[-1].arrival_s, abs=0.5)
    # The fastest curve (today's) waits at stations and reports the windows it misses.
    plan = fastest
    middle = plan.stops[0]
    # the dwell is the difference of the earliest times (300 s), and the departure waits for
    # its earliest time
    assert middle.arrival_s < 300.0
    assert middle.departure_s == pytest.approx(600.0)
    checks = plan.timing
    assert [c.point.position_m for c in checks] == [0, 3500, 6000, 6000, 12000]
    assert checks[2].planned_s == middle.arrival_s and checks[3].planned_s == middle.departure_s
    # arriving before the earliest arrival time is outside the window: reported
    assert [c.within_window for c in checks[:4]] == [True, True, False, True]
    # 6 km from a 600 s departure cannot be done by 700 s at 140 km/h: reported as missed
    assert checks[4].planned_s > 700.0 and not checks[4].within_window
    passing = plan.trajectory.at(checks[1].planned_s)
    assert passing.position == pytest.approx(3500.0, abs=1e-3)
    assert passing.speed <= 60 / 3.6 + 1e-9
