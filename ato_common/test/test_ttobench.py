"""TTOBench tracks, trains and journeys: conversion to SI, validation, every sample track."""

import copy
import json
import math
from pathlib import Path

import pytest
import yaml

from ato_common import units
from ato_common.scenario import load_scenario
from ato_common.ttobench import load_journey, load_track, load_train
from ato_common.validation import ConfigError

# The BSD-2 TTOBench samples ship with the tests (tests/data/ttobench, with their licence), so
# these tests run wherever the repository is cloned.
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


def test_a_track_converts_to_si_with_clothoids_and_tunnel_cross_sections(tmp_path):
    track = load_track(write(tmp_path, 'track.json', TRACK), dwell_s=20.0)
    line = track.line
    assert track.id == 'T_curvy' and line.length_m == 12000.0
    assert [(s.position_m, s.dwell_s) for s in line.stations] == \
        [(0.0, 0.0), (6000.0, 20.0), (12000.0, 0.0)]
    assert line.speed_limit_mps(4500.0) == pytest.approx(80 / 3.6)
    assert line.grade_sine(2500.0) == pytest.approx(units.per_mille_to_sine(8.0))
    g = units.STANDARD_GRAVITY
    grade_force = g * units.per_mille_to_sine(-4.0)
    # transition from straight to R = 2000 m over 200 m: half-way the curvature is 1/4000
    assert line.line_force_per_kg(3100.0) == pytest.approx(grade_force)
    assert line.line_force_per_kg(1100.0) == pytest.approx(g * 600.0 / 4000.0 / 1000.0)
    assert line.line_force_per_kg(1500.0) == pytest.approx(g * 600.0 / 2000.0 / 1000.0)
    # a left-hand (negative) radius resists as much as a right-hand one
    assert line.line_force_per_kg(1725.0) == pytest.approx(g * 600 * 0.75 / 1000.0 / 1000.0)
    assert line.tunnels[0].cross_section_m2 == 40.0 and line.tunnels[0].length_m == 1000.0
    assert track.etcs_kt_int == pytest.approx(1.1)


def test_numbers_in_exponent_form_without_a_dot_are_numbers(tmp_path):
    # TTOBench files are JSON, where 7e3 is a number: not the YAML 1.1 case of scenario files
    # (ato_common.validation.as_number), so the reader keeps refusing numbers given as text.
    text = json.dumps(TRACK).replace('[[7000.0, 1000.0, 40.0]]', '[[7e3, 1E3, 4e+1]]')
    assert '[[7e3, 1E3, 4e+1]]' in text
    path = tmp_path / 'track.json'
    path.write_text(text)
    tunnel = load_track(path).line.tunnels[0]
    assert (tunnel.start_m, tunnel.length_m, tunnel.cross_section_m2) == (7000.0, 1000.0, 40.0)


@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
def test_a_train_converts_to_si():
    train = load_train(SAMPLES / 'trains' / 'CH_Stadler_FLIRT_TPF.json')
    p = train.parameters
    assert p.mass_kg == pytest.approx(122000.0 * 1.10)
    assert p.length_m == pytest.approx(58.6)
    # r0 + r1 V + r2 V^2 kN with V in km/h, at 100 km/h
    expected_n = 1000.0 * (2.37888 + 0.01698165 * 100 + 0.00093264 * 100 ** 2)
    assert p.davis.force(100 / 3.6) == pytest.approx(expected_n, rel=1e-12)
    assert p.traction.max_traction_at(1.0) == pytest.approx(200e3)
    assert p.traction.max_traction_at(100 / 3.6) == pytest.approx(2600e3 / (100 / 3.6))
    # 200 + 1220 kN of regenerative plus pneumatic braking (10.6 m/s^2) bounded by adhesion and
    # by the file's own ETCS service deceleration (0.55 m/s^2 at most) times the mass
    assert p.traction.max_service_brake_force_n == pytest.approx(0.55 * 122000.0 * 1.10)
    assert p.traction.max_emergency_brake_force_n == pytest.approx(0.9 * 122000.0 * 1.10)
    assert p.traction.max_emergency_brake_force_n >= p.traction.max_service_brake_force_n
    assert train.max_speed_mps == pytest.approx(160 / 3.6)
    assert train.efficiency_traction == pytest.approx(0.9)
    assert train.tunnel_resistance[0] == pytest.approx((24.0, 0.0011698e3 * 3.6 ** 2))
    assert train.braking.service[1] == (20.0, 0.5)
    assert train.braking.service_brake_build_up_s == 3.0


def test_a_journey_gives_stations_dwells_and_passing_speed_bounds(tmp_path):
    track = write(tmp_path, 'track.json', TRACK)
    journey = write(tmp_path, 'journey.json', JOURNEY)
    scenario = load_scenario_file(tmp_path, {'line': {'ttobench': 'track.json'},
                                             'journey': {'ttobench': 'journey.json'}})
    stations = scenario.line.stations
    assert [(s.position_m, s.dwell_s) for s in stations] == \
        [(0.0, 0.0), (6000.0, 60.0), (12000.0, 0.0)]
    # the 60 km/h upper bound at 3500 m restricts the line there
    assert scenario.line.speed_limit_mps(3500.5) == pytest.approx(60 / 3.6)
    assert scenario.line.speed_limit_mps(3499.0) == pytest.approx(120 / 3.6)
    parsed = load_journey(journey)
    assert parsed.timing_points[2].latest_s == 330.0
    assert track.exists()


def load_scenario_file(tmp_path, overrides):
    data = {'name': 'tto', 'train': {'preset': 'crh3_luo_xu'},
            'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                         'max_jerk_mps3': 0.3}}
    data.update(overrides)
    path = tmp_path / 'scenario.yaml'
    path.write_text(yaml.safe_dump(data))
    return load_scenario(str(path))


@pytest.mark.parametrize('mutate, message', [
    (lambda d: d.pop('stops'), r'track.json: stops: required field is missing'),
    (lambda d: d['speed limits']['units'].update(velocity='mph'),
     r"speed limits.units.velocity: unit 'mph' is not a speed unit"),
    (lambda d: d['speed limits']['values'].reverse(),
     r'speed limits.values\[0\]: the first entry must start at 0 m'),
    (lambda d: d['gradients']['values'][2].__setitem__(0, 1000.0),
     r'gradients.values\[2\]: positions must strictly increase, got 2000 then 1000 m'),
    (lambda d: d['gradients']['values'][1].__setitem__(1, 'steep'),
     r"gradients.values\[1\]\[1\] \(slope\): must be a number, got 'steep'"),
    (lambda d: d['curvatures']['values'][2].__setitem__(1, 0.0), r'a radius of 0 m'),
    (lambda d: d['tunnels']['values'][0].__setitem__(1, 9000.0), r'beyond the end of the track'),
    (lambda d: d['metadata'].update(id='bad id'), r'metadata.id: must contain only letters'),
    (lambda d: d['stops']['values'].__setitem__(1, float('nan')), r'must be finite'),
    (lambda d: d['speed limits']['values'].append([12500.0, 100]),
     r'not before the end of the track'),
])
def test_a_malformed_track_names_file_field_and_fault(tmp_path, mutate, message):
    data = copy.deepcopy(TRACK)
    mutate(data)
    with pytest.raises(ConfigError, match=message):
        load_track(write(tmp_path, 'track.json', data))


@pytest.mark.parametrize('mutate, message', [
    (lambda d: d['timing points']['values'][1].__setitem__(3, 90),
     r'timing points\[1\]: lower speed 25 m/s is above upper speed 16.6667 m/s'),
    (lambda d: d['timing points']['values'][2].__setitem__(1, 400),
     r'timing points\[2\]: lower time 400 s is after upper time 330 s'),
    (lambda d: d['timing points']['values'][-1].__setitem__(slice(3, 5), [None, None]),
     r'timing points\[4\]: the first and last timing points must be stopping points'),
    (lambda d: d['metadata'].update(id='Other_J1'), r'must start with the associated track'),
    (lambda d: d['timing points']['units'].pop('position'), r"the unit of 'position'"),
])
def test_a_malformed_journey_names_file_field_and_fault(tmp_path, mutate, message):
    data = copy.deepcopy(JOURNEY)
    mutate(data)
    with pytest.raises(ConfigError, match=message):
        load_journey(write(tmp_path, 'journey.json', data))


def test_a_scenario_naming_a_missing_or_broken_file_says_which(tmp_path):
    with pytest.raises(ConfigError, match=r'line.ttobench: no such file .*absent.json'):
        load_scenario_file(tmp_path, {'line': {'ttobench': 'absent.json'}})
    (tmp_path / 'broken.json').write_text('{"metadata": ')
    with pytest.raises(ConfigError, match=r'scenario.yaml: .*broken.json: not valid JSON'):
        load_scenario_file(tmp_path, {'line': {'ttobench': 'broken.json'}})
    write(tmp_path, 'track.json', TRACK)
    with pytest.raises(ConfigError, match=r'line: unknown field\(s\) dwell'):
        load_scenario_file(tmp_path, {'line': {'ttobench': 'track.json', 'dwell': 3}})


def test_the_scenario_command_writes_a_runnable_scenario(tmp_path, capsys):
    from ato_common.scenario_from_ttobench import main
    assert main([str(TRACKS[0]), str(TRAINS[0]), '--dwell', '15']) == 0
    path = tmp_path / 's.yaml'
    path.write_text(capsys.readouterr().out)
    scenario = load_scenario(str(path))
    assert scenario.line.stations[1].dwell_s == 15.0
    assert main([str(tmp_path / 'nope.json'), str(TRAINS[0])]) == 2
    assert 'line.ttobench: no such file' in capsys.readouterr().err
    assert math.isfinite(scenario.train.mass_kg)
