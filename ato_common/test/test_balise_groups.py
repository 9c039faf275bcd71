"""The line's balise groups (``line.balise_groups``): where an on-board odometry relocates the
train. Parsed in SI, validated with the field named, and kept through the scenario's loading
(the MRSP cap at the train's maximum speed rebuilds the line)."""

import pytest

from ato_common.scenario import parse_scenario
from ato_common.validation import ConfigError


def scenario(groups):
    line = {'name': 'l', 'length_m': 10000,
            'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9000}],
            'speed_limits': [{'start_m': 0, 'speed_kmh': 200}]}
    if groups is not None:
        line['balise_groups'] = groups
    return parse_scenario({'name': 't', 'train': {'preset': 'crh3_luo_xu'}, 'line': line,
                           'planning': {'max_acceleration_mps2': 0.5,
                                        'service_deceleration_mps2': 0.6,
                                        'max_jerk_mps3': 0.2}})


def test_balise_groups_are_read_in_metres_and_kept_by_the_scenario():
    s = scenario([{'position_m': 0}, {'position_m': '1.5e3'}, {'position_m': 8800}])
    assert s.line.balise_groups_m == (0.0, 1500.0, 8800.0)
    assert scenario(None).line.balise_groups_m == ()


@pytest.mark.parametrize('groups, message', [
    ([{'position_m': 11000}], r'line.balise_groups\[0\].position_m: must be <= 10000'),
    ([{'position_m': -1}], r'line.balise_groups\[0\].position_m: must be >= 0'),
    ([{'position_m': 500}, {'position_m': 500}],
     r'line.balise_groups\[1\].position_m: positions must increase, got 500 then 500'),
    ([{'position_m': 'far'}], r"line.balise_groups\[0\].position_m: must be a number"),
    ([{'position_m': 5, 'name': 'BG'}], r'line.balise_groups\[0\]: unknown field'),
    ({'position_m': 5}, r'line.balise_groups: must be a list'),
])
def test_a_malformed_balise_group_names_the_field(groups, message):
    with pytest.raises(ConfigError, match=message):
        scenario(groups)
