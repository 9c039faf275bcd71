"""The mode the on-board software takes as active from its measurements."""

import math

from ato_common.scenario import parse_scenario


def scenario_with_region_modes():
    return parse_scenario({
        'name': 's', 'train': {'preset': 'mao_2017_500t'},
        'line': {'name': 'l', 'length_m': 20000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 19000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 200}]},
        'planning': {'max_acceleration_mps2': 0.3, 'service_deceleration_mps2': 0.3,
                     'max_jerk_mps3': 0.3},
        'plant': {'modes': [{'name': 'open', 'from_m': 0},
                            {'name': 'tunnel', 'from_m': 5000,
                             'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 9.2e-4}}]}})


def test_a_missing_position_keeps_the_previous_mode_instead_of_raising():
    plant = scenario_with_region_modes().plant
    assert plant.known_mode(10.0, 6000.0, 0) == 1
    assert plant.known_mode(11.0, math.nan, 1) == 1   # position sensor dropped out
    assert plant.known_mode(12.0, 100.0, 1) == 0
