"""The plant: section of a scenario: parsing, validation with field names, the mode contract."""

import math

import pytest

from ato_common.plant_setup import CURVATURE_ACCEL_PER_D, Disturbance, PlantSetup, parse_plant_setup
from ato_common.scenario import parse_scenario
from ato_common.trains import train_preset
from ato_common.validation import ConfigError

MAO = train_preset('mao_2017_500t')

# Mao, Tao, Jiang, Yan & Zhong 2017 Section 4.1, reading (A) of docs/papers/mao_2017.md.
MAO_PLANT = {
    'modes': [
        {'name': 'accelerating, open air', 'from_s': 0,
         'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 3.2e-4}},
        {'name': 'tunnel', 'from_s': 400, 'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 9.2e-4}},
        {'name': 'slope and curve', 'from_s': 800, 'grade_sine': 0.015, 'curvature': 0.34,
         'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 3.2e-4}},
        {'name': 'braking, open air', 'from_s': 1400,
         'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 3.2e-4}}],
    'failures': [
        {'actuator': 'motor_2', 'kind': 'stuck', 'start_s': 600, 'end_s': 1000, 'force_n': 2e5},
        {'actuator': 'motor_2', 'kind': 'stuck_signal', 'start_s': 1000, 'end_s': 1200,
         'force_n': 2e5, 'amplitude_n': 2e5, 'omega_rad_per_s': 0.05, 'phase_rad': -30},
        {'actuator': 'motor_2', 'kind': 'loss', 'start_s': 1200}],
}


def test_absent_section_means_nothing_varies():
    setup = parse_plant_setup(None, MAO)
    assert setup == PlantSetup()
    assert setup.mode_index(123.0, 4567.0) == 0 and setup.modes == ()
    scenario = parse_scenario({
        'name': 'n', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'l', 'length_m': 1000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 900}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 100}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}})
    assert scenario.plant == PlantSetup()


def test_mao_2017_modes_and_failures_parse_with_the_papers_numbers():
    setup = parse_plant_setup(MAO_PLANT, MAO)
    assert [m.name for m in setup.modes][1] == 'tunnel'
    assert [setup.mode_index(t, 0.0) for t in (0, 399.9, 400, 799, 800, 1399, 1400, 2000)] == \
        [0, 0, 1, 1, 2, 2, 3, 3]
    tunnel, slope = setup.modes[1], setup.modes[2]
    assert tunnel.mass_kg == 500e3
    assert tunnel.davis.c_n_s2_per_m2 == pytest.approx(11.9232)
    assert setup.modes[0].davis == MAO.davis
    assert slope.grade_sine == 0.015
    assert slope.curve_accel_mps2 == pytest.approx(0.004 * 0.34) == CURVATURE_ACCEL_PER_D * 0.34
    stuck, signal, loss = setup.failures
    assert stuck.force(700.0, 1e3) == 2e5
    assert signal.force(1100.0, 1e3) == pytest.approx(2e5 * (1 + math.sin(0.05 * 1100 - 30)))
    assert loss.force(1500.0, 5e4) == 0.0 and math.isinf(loss.end_s)
    assert {600.0, 1000.0, 1200.0, 400.0, 800.0, 1400.0} <= set(setup.scheduled_times())


def test_modes_by_region_switch_on_position():
    setup = parse_plant_setup({'modes': [
        {'from_m': 0}, {'from_m': 5000, 'davis_n': {'a': 3000, 'b': 0, 'c': 12}}]}, MAO)
    assert setup.mode_switch == 'position'
    assert setup.mode_index(9999.0, 4999.0) == 0 and setup.mode_index(0.0, 5000.0) == 1
    assert setup.modes[1].davis.c_n_s2_per_m2 == 12
    with pytest.raises(ValueError, match='position must be finite'):
        setup.mode_index(1.0, math.nan)  # a position not measured has no region


def test_luo_xu_time_varying_resistance_and_tan_abrupt_change():
    setup = parse_plant_setup({
        'resistance_variation': {'a': {'amplitude': 0.3, 'omega_rad_per_s': 0.1},
                                 'b': {'amplitude': 0.2, 'omega_rad_per_s': 0.1},
                                 'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.1}},
        'abrupt_changes': [{'start_s': 1000, 'end_s': 1100, 'grade_per_mille': 30}]}, MAO)
    fa, fb, fc, fl = setup.resistance_variation.factors(5.0)
    assert (fa, fb, fc, fl) == pytest.approx((1 + 0.3 * math.sin(0.5), 1 + 0.2 * math.sin(0.5),
                                              1 + 0.1 * math.sin(0.5), 1.0))
    assert setup.abrupt_change(999.9) is None
    assert setup.abrupt_change(1000.0).grade_sine == pytest.approx(0.03, rel=1e-3)
    assert setup.abrupt_change(1100.0) is None


def test_disturbances_of_liu_li_case_3_and_bounded_random():
    fast = Disturbance('fast', 8900.0, 1.0)
    assert fast.force(0.5) == pytest.approx(8900 * math.sin(0.5))
    slow = Disturbance('slow', 1e4, 2 * math.pi / 6400)
    assert all(-1e4 <= slow.force(t) <= 0.0 for t in range(0, 6400, 50))
    random_a = Disturbance('random', 5e3, hold_s=2.0, seed=4)
    values = [random_a.force(0.5 * k) for k in range(4000)]
    assert max(abs(v) for v in values) <= 5e3 and max(values) > 4e3 and min(values) < -4e3
    assert values[0] == values[3] != values[4]  # held for hold_s
    # the same for any query order and for another instance with the seed
    random_b = Disturbance('random', 5e3, hold_s=2.0, seed=4)
    assert [random_b.force(0.5 * k) for k in reversed(range(4000))] == values[::-1]
    assert Disturbance('random', 5e3, hold_s=2.0, seed=5).force(0.0) != values[0]
    assert random_a.switch_times(0.0, 5.0) == [2.0, 4.0]


def test_sensors_and_actuators_parse():
    setup = parse_plant_setup({
        'actuators': {'time_constant_s': 0.5, 'rate_limit_n_per_s': 1e5},
        'sensors': {'seed': 3, 'speed': {'noise_std': 0.01, 'failed_from_s': 300,
                                         'failed_cars': ['train']},
                    'position': {'quantum': 0.1, 'bias': 1.0, 'dropout_probability': 0.1}}}, MAO)
    assert setup.actuators.time_constant_s == 0.5 and setup.actuators.rate_limit_n_per_s == 1e5
    assert setup.sensors.speed.failed(300.0, 'train') and not setup.sensors.speed.failed(299.9,
                                                                                          'train')
    assert setup.sensors.position.quantum == 0.1 and not setup.sensors.ideal
    assert 300.0 in setup.scheduled_times()


@pytest.mark.parametrize('plant, message', [
    ({'modes': [{'from_s': 5}]}, r'plant.modes\[0\].from_s: the first mode must start at 0'),
    ({'modes': [{'from_s': 0}, {'from_m': 10}]}, r'plant.modes\[1\]: every mode needs from_s'),
    ({'modes': [{'from_s': 0}, {'from_s': 0}]}, r'plant.modes\[1\].from_s: must increase'),
    ({'modes': [{'from_s': 0, 'grade_sine': 0.01, 'grade_per_mille': 3}]}, 'not both'),
    ({'failures': [{'actuator': 'motor_9', 'kind': 'loss', 'start_s': 1}]},
     r"plant.failures\[0\].actuator: unknown actuator 'motor_9'; valid: motor_1"),
    ({'failures': [{'actuator': 'motor_1', 'kind': 'melted', 'start_s': 1}]}, 'kind'),
    ({'failures': [{'actuator': 'motor_1', 'kind': 'partial', 'start_s': 1,
                    'effectiveness': 1.5}]}, r'effectiveness: must be <= 1'),
    ({'failures': [{'actuator': 'motor_1', 'kind': 'loss', 'start_s': 1},
                   {'actuator': 'motor_1', 'kind': 'loss', 'start_s': 5}]}, 'overlaps'),
    ({'disturbance': {'kind': 'fast', 'amplitude_n': float('nan')}}, 'must be finite'),
    ({'sensors': {'speed': {'noise_std': -1}}}, r'plant.sensors.speed.noise_std: must be >= 0'),
    ({'sensors': {'speed': {'failed_cars': ['car_9']}}}, "unknown car 'car_9'"),
    ({'abrupt_changes': [{'start_s': 10, 'end_s': 5, 'grade_per_mille': 3}]}, 'end_s: must be >'),
    ({'actuators': {'lag_s': 1}}, r'plant.actuators: unknown field\(s\) lag_s'),
    ({'resistance_variation': {'a': {'amplitude': 2, 'omega_rad_per_s': 1}}}, 'must be <= 1'),
])
def test_bad_plant_sections_are_rejected_naming_the_field(plant, message):
    with pytest.raises(ConfigError, match=message):
        parse_plant_setup(plant, MAO)


def test_run_time_failure_injection_defaults_to_now_and_can_repair():
    from ato_common.plant_setup import parse_failure_injection
    failures, repaired = parse_failure_injection(
        '{actuator: motor_3, kind: stuck, force_n: 1.5e+5}', MAO.actuator_names, 42.0)
    assert failures[0].start_s == 42.0 and failures[0].force_n == 1.5e5 and not repaired
    failures, repaired = parse_failure_injection(
        '[{actuator: motor_1, kind: healthy}, {actuator: motor_2, kind: loss, start_s: 50}]',
        MAO.actuator_names, 42.0)
    assert repaired == ('motor_1',) and failures[0].kind == 'loss'
    assert parse_failure_injection('', MAO.actuator_names, 1.0) == ((), ())
    for text, message in (('{actuator: motor_1, kind: loss, start_s: 3}', 'in the past'),
                          ('{actuator: x, kind: healthy}', "unknown actuator 'x'"),
                          ('[unclosed', 'not valid YAML'),
                          ('{actuator: motor_1, kind: stuck}', r'inject_failure\[0\].force_n')):
        with pytest.raises(ConfigError, match=message):
            parse_failure_injection(text, MAO.actuator_names, 42.0)


def test_any_plant_section_gives_a_setup_or_a_config_error():
    from hypothesis import given, settings
    from hypothesis import strategies as st
    leaves = st.none() | st.booleans() | st.integers(-5, 5) | st.floats() | st.text(max_size=5)
    values = st.recursive(leaves, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
        st.sampled_from(['a', 'kind', 'from_s', 'actuator', 'failed_cars', 'speed', 'modes',
                         'failures', 'sensors', 'amplitude', 'force_n', 'start_s']), inner,
        max_size=4), max_leaves=12)
    sections = st.dictionaries(st.sampled_from(
        ['resistance_variation', 'modes', 'abrupt_changes', 'disturbance', 'actuators',
         'failures', 'sensors']), values, max_size=3)

    @settings(max_examples=150, deadline=None)
    @given(sections)
    def check(data):
        try:
            assert isinstance(parse_plant_setup(data, MAO), PlantSetup)
        except ConfigError:
            pass
    check()
