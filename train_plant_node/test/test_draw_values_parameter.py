"""The plant's ``draw_values`` parameter (train_plant_node.draw_values): the truth of one draw of a
campaign, as JSON; bad text is refused with a reason that names what is wrong, and a draw's
values go through the text to the same truth, bit for bit."""

import math

import pytest

from ato_common.scenario import load_scenario
from ato_common.uncertainty import DEFAULTS, PARAMETERS, PLANT_PARAMETERS, draw, perturbed
from ato_common.validation import ConfigError
from train_plant_node.draw_values import draw_values_text, parse_draw_values


def test_empty_text_is_the_nominal_plant_and_a_parameter_left_out_is_nominal():
    assert parse_draw_values('') is None
    assert parse_draw_values('  ') is None
    nominal = {name: PARAMETERS[name].nominal for name in PLANT_PARAMETERS}
    assert parse_draw_values('{}') == nominal
    values = parse_draw_values('{"mass_factor": 1.1, "wind_mps": -4}')
    assert values == {**nominal, 'mass_factor': 1.1, 'wind_mps': -4.0}
    assert 'gradient_known' not in values  # the plant is never told what the controller knows


@pytest.mark.parametrize('text, words', [
    ('{"mass_factor": 1.1', ['draw_values: not JSON']),
    ('mass_factor=1.1', ['draw_values: not JSON']),
    ('[1.1]', ['must be a JSON object', 'list']),
    ('1.1', ['must be a JSON object', 'float']),
    ('{"mass_facter": 1.1}', ["unknown field(s) mass_facter; did you mean mass_factor?"]),
    ('{"gradient_known": 0}', ['draw_values.gradient_known', 'controller',
                               'gradient_known parameter']),
    ('{"mass_factor": 2.5}', ['draw_values.mass_factor', '[0.5, 2]', '2.5']),
    ('{"wind_mps": -30}', ['draw_values.wind_mps', '[-25, 25] m/s']),
    ('{"mass_factor": NaN}', ['draw_values: not JSON', 'NaN']),
    ('{"mass_factor": Infinity}', ['draw_values: not JSON', 'Infinity']),
    ('{"mass_factor": 1e999}', ['draw_values.mass_factor', 'finite']),
    ('{"mass_factor": "1.1"}', ['draw_values.mass_factor', "'1.1'"]),
    ('{"mass_factor": true}', ['draw_values.mass_factor', 'True']),
    ('{"mass_factor": null}', ['draw_values.mass_factor', 'None']),
])
def test_bad_draw_values_are_refused_naming_what_is_wrong(text, words):
    with pytest.raises(ConfigError) as refused:
        parse_draw_values(text)
    for word in words:
        assert word in str(refused.value)


def test_a_draw_through_its_text_gives_the_same_truth_bit_for_bit():
    scenario = load_scenario('short_line')
    for index in range(5):
        values = draw(DEFAULTS, 2028, index)
        parsed = parse_draw_values(draw_values_text(values))
        assert parsed == {name: values[name] for name in PLANT_PARAMETERS}
        assert all(math.copysign(1.0, parsed[n]) == math.copysign(1.0, values[n])
                   for n in parsed)
        assert perturbed(scenario, parsed) == perturbed(scenario, values)
