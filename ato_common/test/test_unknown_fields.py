"""Issue 14, defect 3: no field of a TTOBench file or of the suite's YAML is silently ignored.
An unknown field is an error naming the file, the field, the likely intended name and the valid
names; a misspelt required field of the suite's YAML is named as the typo it is."""

import copy
import json
from pathlib import Path

import pytest
import yaml

from ato_common.scenario import load_scenario, parse_scenario
from ato_common.ttobench import load_journey, load_track, load_train
from ato_common.validation import ConfigError

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
FLIRT = SAMPLES / 'trains' / 'CH_Stadler_FLIRT_TPF.json'

TRACK = {
    'metadata': {'id': 'T_typo', 'library version': 'TTOBench v1.5', 'license': 'BSD-2'},
    'altitude': {'unit': 'm', 'value': 500.0},
    'stops': {'unit': 'm', 'values': [0.0, 6000.0]},
    'speed limits': {'units': {'position': 'm', 'velocity': 'km/h'},
                     'values': [[0.0, 120], [4000.0, 80]]},
    'gradients': {'units': {'position': 'm', 'slope': 'permil'}, 'values': [[0.0, 2.0]]},
    'curvatures': {'units': {'position': 'm', 'radius at start': 'm', 'radius at end': 'm'},
                   'values': [[0.0, 'infinity', 'infinity'], [1000.0, 800.0, 800.0],
                              [1500.0, 'infinity', 'infinity']]},
    'ETCS braking data': {'M_NVAVADH': {'unit': '-', 'value': 0.0},
                          'Kt_int': {'unit': '-', 'value': 1.1}},
}

JOURNEY = {
    'metadata': {'id': 'T_typo_J1', 'associated track': 'T_typo',
                 'library version': 'TTOBench v1.5'},
    'timing points': {'units': {'position': 'm', 'lower time constraint': 's',
                                'upper time constraint': 's', 'lower speed constraint': 'km/h',
                                'upper speed constraint': 'km/h'},
                      'values': [[0, 0, 0, 0, 0], [6000, 300, 400, 0, 0]]},
}


def write(tmp_path, name, data):
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def rename(mapping, old, new):
    mapping[new] = mapping.pop(old)


def test_the_valid_track_loads_with_its_curve(tmp_path):
    assert len(load_track(write(tmp_path, 'track.json', TRACK)).line.curves) == 1


def test_a_misspelt_curvatures_is_rejected_not_a_straight_track(tmp_path):
    data = copy.deepcopy(TRACK)
    rename(data, 'curvatures', 'curvatrues')
    path = write(tmp_path, 'track.json', data)
    with pytest.raises(ConfigError) as error:
        load_track(path)
    message = str(error.value)
    assert str(path) in message
    assert "unknown field(s) 'curvatrues'; did you mean 'curvatures'?" in message
    for valid in ('metadata', 'stops', 'speed limits', 'gradients', 'tunnels',
                  'ETCS braking data'):
        assert repr(valid) in message


def test_a_misspelt_braking_force_is_rejected_not_a_third_of_the_braking(tmp_path):
    data = json.loads(FLIRT.read_text())
    rename(data, 'max pn braking force', 'max pn brakng force')
    path = write(tmp_path, 'train.json', data)
    message = (r"train.json: unknown field\(s\) 'max pn brakng force'; "
               r"did you mean 'max pn braking force'\? \(valid fields: ")
    with pytest.raises(ConfigError, match=message):
        load_train(path)


@pytest.mark.parametrize('mutate, where, field', [
    (lambda d: rename(d['metadata'], 'license', 'licence'), 'metadata', 'licence'),
    (lambda d: rename(d['ETCS braking data'], 'Kt_int', 'Kt_Int'), 'ETCS braking data',
     'Kt_Int'),
    (lambda d: d['altitude'].update(units='m'), 'altitude', 'units'),
    (lambda d: d['speed limits'].update(value=[]), 'speed limits', 'value'),
    (lambda d: rename(d['gradients']['units'], 'slope', 'slop'), 'gradients.units', 'slop'),
    (lambda d: d['stops'].update(units={'position': 'm'}), 'stops', 'units'),
])
def test_an_unknown_field_inside_a_track_names_where(tmp_path, mutate, where, field):
    data = copy.deepcopy(TRACK)
    mutate(data)
    with pytest.raises(ConfigError, match=rf"track.json: {where}: unknown field\(s\) '{field}'"):
        load_track(write(tmp_path, 'track.json', data))


@pytest.mark.parametrize('mutate, where, field', [
    (lambda d: rename(d['ETCS braking data'], 'T_bs', 'Tbs'), 'ETCS braking data', 'Tbs'),
    (lambda d: d['mass'].update(unti='t'), 'mass', 'unti'),
    (lambda d: rename(d['tunnel resistance']['units'], 'coefficient', 'coef'),
     'tunnel resistance.units', 'coef'),
])
def test_an_unknown_field_inside_a_train_names_where(tmp_path, mutate, where, field):
    data = json.loads(FLIRT.read_text())
    mutate(data)
    with pytest.raises(ConfigError, match=rf"train.json: {where}: unknown field\(s\) '{field}'"):
        load_train(write(tmp_path, 'train.json', data))


@pytest.mark.parametrize('mutate, where, field', [
    (lambda d: d.update(comment='x'), '', 'comment'),
    (lambda d: rename(d['metadata'], 'associated track', 'associated_track'), 'metadata: ',
     'associated_track'),
    (lambda d: rename(d['timing points']['units'], 'position', 'positon'),
     'timing points.units: ', 'positon'),
])
def test_an_unknown_field_of_a_journey_names_where(tmp_path, mutate, where, field):
    write(tmp_path, 'track.json', TRACK)
    data = copy.deepcopy(JOURNEY)
    mutate(data)
    with pytest.raises(ConfigError, match=rf"journey.json: {where}.*unknown field\(s\) "
                                          rf"'{field}'"):
        load_journey(write(tmp_path, 'journey.json', data))


@pytest.mark.parametrize('path', sorted(SAMPLES.glob('*/*.json')), ids=lambda p: p.stem)
def test_every_sample_file_has_only_known_fields(path):
    loader = {'tracks': load_track, 'trains': load_train, 'journeys': load_journey}
    loader[path.parent.name](path)


def valid_scenario():
    return {'name': 'p', 'train': {'preset': 'crh3_luo_xu'},
            'line': {'name': 'l', 'length_m': 10000,
                     'stations': [{'name': 'A', 'position_m': 0},
                                  {'name': 'B', 'position_m': 9000}],
                     'speed_limits': [{'start_m': 0, 'speed_kmh': 200}],
                     'gradients': [{'start_m': 0, 'per_mille': 2.0}]}}


def test_a_misspelt_required_key_of_the_suites_yaml_is_named_as_a_typo():
    data = valid_scenario()
    rename(data['line']['gradients'][0], 'per_mille', 'per_mile')
    with pytest.raises(ConfigError, match=r'^line.gradients\[0\]: unknown field per_mile; did you '
                                          r'mean per_mille\?'):
        parse_scenario(data)
    data = valid_scenario()
    rename(data['line'], 'speed_limits', 'speed_limit')
    with pytest.raises(ConfigError, match=r'^line: unknown field speed_limit; did you mean '
                                          r'speed_limits\?'):
        parse_scenario(data)


def test_a_missing_required_key_without_a_lookalike_is_reported_missing():
    data = valid_scenario()
    data['line']['gradients'][0] = {'start_m': 0, 'slope': 2.0}
    with pytest.raises(ConfigError, match=r'line.gradients\[0\].per_mille: required number is '
                                          r'missing'):
        parse_scenario(data)
    # a valid field read later is not taken for the typo of a missing one
    data = valid_scenario()
    data['line']['curves'] = [{'start_m': 100, 'length_m': 50, 'end_radius_m': 900}]
    with pytest.raises(ConfigError, match=r'line.curves\[0\].radius_m: required number is '
                                          r'missing'):
        parse_scenario(data)


def test_an_unknown_optional_key_of_the_suites_yaml_names_the_likely_one(tmp_path):
    data = valid_scenario()
    data['line']['stations'][0]['dwel_s'] = 30
    path = tmp_path / 's.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r'unknown field\(s\) dwel_s; did you mean dwell_s\? '
                                          r'\(valid fields: dwell_s, name, position_m\)'):
        load_scenario(str(path))


def test_a_required_key_written_without_its_unit_suffix_is_named_as_the_typo():
    from ato_common.validation import ConfigError, Fields
    fields = Fields({'max_jerk': 0.1}, 'planning')
    with pytest.raises(ConfigError, match='unknown field max_jerk; did you mean max_jerk_mps3'):
        fields.number('max_jerk_mps3')
