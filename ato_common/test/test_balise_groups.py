"""The line's balise groups (``line.balise_groups``): where an on-board odometry relocates the
train. Parsed in SI, validated with the field named, and kept through the scenario's loading
(the MRSP cap at the train's maximum speed rebuilds the line); a line that declares none gets
the default placement (``default_balise_groups``), every built-in scenario among them."""

from importlib import resources

import numpy as np
import pytest

from ato_common.line import (
    BALISE_GROUP_SPACING_M,
    BALISE_GROUPS_BEFORE_STOP_M,
    default_balise_groups,
)
from ato_common.scenario import load_scenario, parse_scenario
from ato_common.validation import ConfigError

BUILT_IN = sorted(p.name.removesuffix('.yaml') for p in
                  resources.files('ato_common').joinpath('scenarios').iterdir()
                  if p.name.endswith('.yaml'))


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
    assert scenario([]).line.balise_groups_m == ()   # declared: none at all


def test_a_line_that_declares_none_gets_the_default_placement():
    s = scenario(None)
    groups = s.line.balise_groups_m
    assert groups == default_balise_groups(s.line)
    assert {9000.0 - d for d in BALISE_GROUPS_BEFORE_STOP_M} <= set(groups)
    assert 0.0 < groups[0] <= BALISE_GROUP_SPACING_M   # ahead of the start: it corrects it
    assert np.diff((0.0,) + groups + (10000.0,)).max() <= BALISE_GROUP_SPACING_M


@pytest.mark.parametrize('name', BUILT_IN)
def test_every_built_in_scenario_has_balise_groups_and_declares_its_odometry(name):
    """The rule of docs/guide/scenarios.md: groups at most 1.5 km apart over the whole line,
    one 200 m and one 20 m before each stop; the odometry's SUBSET-041 accuracy."""
    s = load_scenario(name)
    groups = s.line.balise_groups_m
    assert np.diff((0.0,) + groups + (s.line.length_m,)).max() <= BALISE_GROUP_SPACING_M + 1e-6
    for station in s.line.stations[1:]:
        for d in BALISE_GROUPS_BEFORE_STOP_M:
            assert station.position_m - d in groups
    o = s.supervision
    assert (o.location_accuracy_m, o.odometry_accuracy, o.speed_accuracy_share) == \
        (5.0, 0.05, 0.02) and o.speed_accuracy_mps == pytest.approx(2.0 / 3.6, abs=1e-4)


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
