"""Files checked on load (issue 30): a gradient no adhesion railway has and figures that a unit
read wrong makes absurd are refused naming the file and the field; signed curve radii (TTOBench:
left-hand curves negative) are accepted in the suite's schema and resist by their magnitude."""

import copy
import json
from pathlib import Path

import pytest

from ato_common import units
from ato_common.scenario import parse_scenario
from ato_common.ttobench import load_track, load_train
from ato_common.validation import ConfigError

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
SYNTHETIC = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'synthetic'
TRACK = json.loads((SYNTHETIC / 'ttobench_track_T_curvy.json').read_text())
KISS = json.loads((SAMPLES / 'trains' / 'CH_Stadler_KISS_SBB.json').read_text())
G = units.STANDARD_GRAVITY


def write(tmp_path, name, data) -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def test_a_track_steeper_than_any_adhesion_railway_is_refused_naming_file_and_field(tmp_path):
    data = copy.deepcopy(TRACK)
    data['gradients']['values'][1][1] = 200.0
    path = write(tmp_path, 'steep.json', data)
    with pytest.raises(ConfigError, match=r'steep.json: gradients.values\[1\]: 200 per mille is '
                                          r'steeper than any line worked by adhesion \(at most '
                                          r'140 per mille'):
        load_track(path)
    data['gradients']['values'][1][1] = -140.0
    assert load_track(write(tmp_path, 'ok.json', data)).line.grade_sine(2500.0) == \
        pytest.approx(units.per_mille_to_sine(-140.0))


@pytest.mark.parametrize('key, entry, message', [
    # the case: a mass in kg declared in t loads a thousand times too heavy
    ('mass', {'unit': 't', 'value': 297000.0},
     r"mass.value: 297000 t over a length of 150 m \(not in the file: 25 m per coach\) is "
     r"1980 t/m, outside the 0.3-20 t/m of real trains: a wrong figure or unit \(the file "
     r"declares 't'\)"),
    ('mass', {'unit': 'kg', 'value': 297.0}, r'mass.value: .* t/m, outside'),
    ('max traction force', {'unit': 'N', 'value': 400.0},
     r"max traction force.value: the traction force over the weight is .* outside the "
     r"0.002-2 x weight of real trains: a wrong figure or unit \(the file declares 'N'\)"),
    ('max pn braking force', {'unit': 'kN', 'value': 2.97e6},
     r'max reg braking force.value: the regenerative plus pneumatic braking force over the '
     r'weight is'),
    ('max traction power', {'unit': 'MW', 'value': 6000.0},
     r"max traction power.value: the traction power per tonne is .* kW/t, outside the "
     r"0.2-100 kW/t .*'MW'"),
    ('max traction power', {'unit': 'W', 'value': 6000.0}, r'max traction power.value'),
    ('rolling resistance r2', {'unit': 'kN/(km/h)^2', 'value': 1.21104},
     r'rolling resistance r0: the running resistance at the maximum speed is .* x the weight'),
])
def test_a_train_figure_a_wrong_unit_makes_absurd_is_refused_naming_the_field(
        tmp_path, key, entry, message):
    data = copy.deepcopy(KISS)
    data[key] = entry
    path = write(tmp_path, 'train.json', data)
    with pytest.raises(ConfigError, match=f'train.json: {message}'):
        load_train(path)


@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
def test_every_sample_train_is_plausible():
    for path in sorted((SAMPLES / 'trains').glob('*.json')):
        assert load_train(path).parameters.mass_kg > 0.0


def scenario(curves, per_mille=10.0):
    return parse_scenario({
        'name': 't', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'l', 'length_m': 10000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 200}],
                 'gradients': [{'start_m': 5000, 'per_mille': per_mille}],
                 'curves': curves},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.6,
                     'max_jerk_mps3': 0.2}})


def test_signed_radii_are_accepted_and_resist_by_their_magnitude():
    line = scenario([{'start_m': 1000, 'length_m': 500, 'radius_m': -3000},
                     {'start_m': 2000, 'length_m': 500, 'radius_m': 3000},
                     # an S-transition: from 1000 m right-hand to 1000 m left-hand
                     {'start_m': 3000, 'length_m': 400, 'radius_m': 1000,
                      'end_radius_m': -1000}]).line
    curve = G * 600.0 / 3000.0 / 1000.0
    assert line.line_force_per_kg(1200.0) == pytest.approx(curve)
    assert line.line_force_per_kg(2200.0) == pytest.approx(curve)
    # straight half-way, and linear in the magnitude on each side
    assert line.line_force_per_kg(3200.0) == pytest.approx(0.0, abs=1e-12)
    assert line.line_force_per_kg(3100.0) == pytest.approx(G * 600.0 / 2000.0 / 1000.0)
    assert line.line_force_per_kg(3300.0) == pytest.approx(G * 600.0 / 2000.0 / 1000.0)
    assert [c.start_m for c in line.curves] == [1000.0, 2000.0, 3000.0, 3200.0]


def test_a_gradient_beyond_the_adhesion_bound_is_refused_in_the_suites_schema():
    assert scenario([], per_mille=-140.0).line.grade_sine(6000.0) < 0.0
    with pytest.raises(ConfigError, match=r'line.gradients\[0\].per_mille: must be <= 140'):
        scenario([], per_mille=200.0)
