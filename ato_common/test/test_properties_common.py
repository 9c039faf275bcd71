"""Property-based tests: random and extreme input to the line loader gives either a valid result
or the documented error, never anything else (the message conversions: ato_ros/test)."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common.scenario import parse_scenario
from ato_common.validation import ConfigError

anything = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4) |
    st.dictionaries(st.text(max_size=12), children, max_size=4), max_leaves=12)

numbers = st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10**6, 10**6)


def valid():
    return {'name': 'p', 'train': {'preset': 'crh3_luo_xu'},
            'line': {'name': 'l', 'length_m': 10000,
                     'stations': [{'name': 'A', 'position_m': 0},
                                  {'name': 'B', 'position_m': 9000}],
                     'speed_limits': [{'start_m': 0, 'speed_kmh': 200}]},
            'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.6,
                         'max_jerk_mps3': 0.2}}


@settings(max_examples=300, deadline=None)
@given(anything)
def test_any_document_loads_or_raises_config_error(document):
    try:
        parse_scenario(document)
    except ConfigError:
        pass


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([('line', 'length_m'), ('planning', 'max_jerk_mps3'),
                        ('planning', 'max_acceleration_mps2')]), anything)
def test_any_value_in_a_field_loads_or_raises_config_error(field, value):
    document = valid()
    document[field[0]][field[1]] = value
    try:
        scenario = parse_scenario(document)
    except ConfigError as error:
        assert str(error).startswith(('line.', 'planning.'))  # names the field at fault
    else:
        assert math.isfinite(getattr(scenario.planning, field[1], 1.0))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(numbers, numbers), min_size=0, max_size=5))
def test_any_station_list_loads_or_raises_config_error(positions):
    document = valid()
    document['line']['stations'] = [{'name': f's{i}', 'position_m': p, 'dwell_s': d}
                                    for i, (p, d) in enumerate(positions)]
    try:
        scenario = parse_scenario(document)
    except ConfigError:
        return
    stations = [s.position_m for s in scenario.line.stations]
    assert stations == sorted(stations) and all(math.isfinite(p) for p in stations)
