import copy

import pytest
import yaml

from ato_common.scenario import builtin_scenarios, load_scenario, parse_scenario
from ato_common.validation import ConfigError, as_number


def base():
    return {
        'name': 't', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'l', 'length_m': 10000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 200}],
                 'gradients': [{'start_m': 0, 'per_mille': 0}, {'start_m': 5000, 'per_mille': 10}],
                 'curves': [{'start_m': 1000, 'length_m': 500, 'radius_m': 3000}],
                 'tunnels': [{'start_m': 2000, 'length_m': 1000}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.6,
                     'max_jerk_mps3': 0.2}}


def test_builtin_scenarios_load():
    assert 'short_line' in builtin_scenarios()
    for name in builtin_scenarios():
        scenario = load_scenario(name)
        assert scenario.name == name
        assert len(scenario.line.stations) >= 2


def test_line_lookups_in_si():
    s = parse_scenario(base())
    assert s.line.speed_limit_mps(100.0) == pytest.approx(200 / 3.6)
    assert s.line.grade_sine(4999.0) == 0.0
    assert s.line.grade_sine(5000.0) == pytest.approx(0.01, rel=1e-4)
    g = 9.80665
    # curve 600/R N/kN, tunnel 0.00013 L N/kN
    assert s.line.line_force_per_kg(1200.0) == pytest.approx(g * 600 / 3000 / 1000)
    assert s.line.line_force_per_kg(2500.0) == pytest.approx(g * 0.00013 * 1000 / 1000)
    assert s.line.line_force_per_kg(100.0) == 0.0


@pytest.mark.parametrize('mutate, message', [
    (lambda d: d['line']['stations'][1].update(position_m='far'),
     r"line.stations\[1\].position_m: must be a number, got 'far'"),
    (lambda d: d['line']['stations'][1].update(position_m='nan'),
     r"line.stations\[1\].position_m: must be a number, got 'nan'"),
    (lambda d: d['line']['stations'][1].update(position_m='-inf'),
     r"line.stations\[1\].position_m: must be a number, got '-inf'"),
    (lambda d: d['line']['stations'][1].update(position_m=True),
     r'line.stations\[1\].position_m: must be a number, got True'),
    (lambda d: d['line']['stations'][1].update(position_m='9e3 m'),
     r"line.stations\[1\].position_m: must be a number, got '9e3 m'"),
    (lambda d: d['line']['stations'][1].update(position_m='1e999'),
     r'line.stations\[1\].position_m: must be finite, got inf'),
    (lambda d: d['line']['stations'][1].update(position_m=20000),
     r'line.stations\[1\].position_m: must be <= 10000'),
    (lambda d: d['line']['stations'].reverse(), r'positions must increase'),
    (lambda d: d['line'].update(stations=[{'name': 'A', 'position_m': 0}]), r'at least two'),
    (lambda d: d['line']['speed_limits'][0].update(speed_kmh=-5), r'speed_kmh: must be >'),
    (lambda d: d['line']['speed_limits'][0].update(start_m=10), r'must start at 0 m'),
    (lambda d: d['line']['gradients'][1].update(start_m=0.0), r'start_m must increase'),
    (lambda d: d['line'].update(stations_typo=[]), r'unknown field\(s\) stations_typo'),
    (lambda d: d['train'].update(preset='maglev'), r"unknown train 'maglev'; valid: crh"),
    (lambda d: d.pop('planning'), r'planning: required section is missing'),
    (lambda d: d['planning'].update(max_jerk_mps3=float('nan')), r'max_jerk_mps3: must be'),
    (lambda d: d['line'].update(curves=[{'start_m': 0, 'length_m': 10, 'radius_m': 0}]),
     r'radius_m: a radius of 0 m is not a curve'),
    (lambda d: d.update(run={'initial_position_m': 500}),
     r'run.initial_position_m: the run starts at a station'),
    (lambda d: d['train'].update(mass_t=600), r'unknown field\(s\) mass_t'),
])
def test_malformed_scenarios_name_the_field(mutate, message):
    data = copy.deepcopy(base())
    mutate(data)
    with pytest.raises(ConfigError, match=message):
        parse_scenario(data)


def test_files_errors_name_the_file(tmp_path):
    missing = tmp_path / 'nope.yaml'
    with pytest.raises(ConfigError, match='neither a built-in scenario'):
        load_scenario(str(missing))
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: [unclosed\n')
    with pytest.raises(ConfigError, match=f'{broken}: not valid YAML'):
        load_scenario(str(broken))
    wrong = tmp_path / 'wrong.yaml'
    data = base()
    data['line']['length_m'] = 'long'
    wrong.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=f'{wrong}: line.length_m: must be a number'):
        load_scenario(str(wrong))


@pytest.mark.parametrize('value, number', [
    (2, 2.0), (2.5, 2.5), ('2e5', 2e5), ('-1.5E-3', -1.5e-3), ('+3', 3.0), ('.5', 0.5),
    ('7.', 7.0), ('1.25e+2', 125.0),
    (True, None), (False, None), ('nan', None), ('inf', None), ('.inf', None),
    ('Infinity', None), ('', None), (' 2e5', None), ('1_000', None), ('0x10', None),
    ('e5', None), ('2e', None), ('far', None), (None, None), ([1.0], None)])
def test_as_number_takes_numbers_and_float_text_only(value, number):
    assert as_number(value) == number


def test_numbers_in_exponent_form_without_a_dot_load_from_yaml(tmp_path):
    # PyYAML reads YAML 1.1, where 2e5 and -1.5E-3 are text; YAML 1.2 and Python read numbers.
    data = base()
    del data['line']['length_m']
    path = tmp_path / 'exponents.yaml'
    path.write_text(yaml.safe_dump(data) + 'plant:\n'
                    '  disturbance: {kind: fast, amplitude_n: 2e5, phase_rad: -1.5E-3}\n')
    text = path.read_text().replace('line:\n', 'line:\n  length_m: 1e4\n', 1)
    path.write_text(text)
    assert yaml.safe_load(text)['line']['length_m'] == '1e4'  # the premise: text, not a number
    scenario = load_scenario(str(path))
    assert scenario.line.length_m == 10000.0
    assert scenario.plant.disturbance.amplitude_n == 2e5
    assert scenario.plant.disturbance.phase_rad == -1.5e-3


def test_an_uncertainty_section_is_parsed_with_the_campaign_schema_and_named_errors(tmp_path):
    from importlib import resources

    from ato_common import uncertainty as u
    data = yaml.safe_load((resources.files('ato_common') / 'scenarios' / 'short_line.yaml')
                          .read_text())
    assert load_scenario('short_line').uncertainty is None
    data['uncertainty'] = {'defaults': False, 'wind_mps': {'dist': 'uniform', 'low': -2,
                                                           'high': 2}}
    path = tmp_path / 'windy.yaml'
    path.write_text(yaml.safe_dump(data))
    spec = load_scenario(str(path)).uncertainty
    assert spec['wind_mps'] == u.Distribution('uniform', -2.0, 2.0)
    assert spec['mass_factor'] == u.NOMINAL['mass_factor']
    data['uncertainty'] = {'wind_mps': {'dist': 'uniform', 'low': 2, 'high': -2}}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=rf'{path}: uncertainty.wind_mps: high .* above low'):
        load_scenario(str(path))
    data['uncertainty'] = {'odometer_scale': 0.01}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=rf'{path}: uncertainty.odometer_scale: unknown'):
        load_scenario(str(path))


def test_the_timetable_section_chooses_the_strategy_with_documented_defaults():
    default = parse_scenario(base()).timetable
    # no times given: the fastest curve, a 7 % supplement if timetable is asked for
    assert (default.strategy, default.supplement_percent, default.run_infeasible,
            default.replan_delay_s) == ('fastest', 7.0, False, 10.0)
    data = base()
    data['timetable'] = {'strategy': 'timetable', 'supplement_percent': 12,
                         'run_infeasible': True, 'replan_delay_s': 0}
    chosen = parse_scenario(data).timetable
    assert (chosen.strategy, chosen.supplement_percent, chosen.run_infeasible,
            chosen.replan_delay_s) == ('timetable', 12.0, True, 0.0)


@pytest.mark.parametrize('section, message', [
    ({'strategy': 'slowest'}, "timetable.strategy: unknown strategy 'slowest'; valid: fastest, "
                              'timetable'),
    ({'supplement_percent': -1}, 'timetable.supplement_percent: must be >= 0, got -1'),
    ({'run_infeasible': 'yes'}, "timetable.run_infeasible: must be true or false, got 'yes'"),
    ({'suplement_percent': 5}, 'did you mean supplement_percent'),
])
def test_a_malformed_timetable_section_names_the_field(section, message):
    data = base()
    data['timetable'] = section
    with pytest.raises(ConfigError, match=message.replace('(', r'\(').replace(')', r'\)')):
        parse_scenario(data)
