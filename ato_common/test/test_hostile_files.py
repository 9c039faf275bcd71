"""Hostile files (issue 29, item 5): deep nesting, alias bombs, keys given twice and a tunnel past
the line's end are refused with an error naming the file and the field, in bounded time and
memory; any bytes at all give a scenario or a ConfigError."""

import json
import re
from importlib import resources
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ato_common import files
from ato_common.files import MAX_DEPTH, load_json, load_yaml, load_yaml_text
from ato_common.plant_setup import parse_failure_injection
from ato_common.scenario import Scenario, load_scenario
from ato_common.ttobench import load_track, load_train
from ato_common.validation import ConfigError

SHORT_LINE = (resources.files('ato_common') / 'scenarios' / 'short_line.yaml').read_text()
SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
TRAIN = json.loads((SAMPLES / 'trains' / 'CH_Stadler_FLIRT_TPF.json').read_text())
TRACK = json.loads((SAMPLES / 'tracks' / '00_reference_with_tunnels.json').read_text())


def alias_bomb(levels: int = 9) -> str:
    """A flow list whose aliases stand for 9**levels strings ('billion laughs')."""
    lines = ['  - &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]']
    for i in range(1, levels):
        lines.append(f'  - &l{i} [' + ', '.join([f'*l{i - 1}'] * 9) + ']')
    return '\n'.join(lines)


def with_field(key: str, value: str) -> str:
    """short_line with the top-level ``key`` given as the YAML ``value``."""
    kept = [line for line in SHORT_LINE.splitlines() if not line.startswith(f'{key}:')]
    return '\n'.join(kept) + f'\n{key}:{value}\n'


def refused(tmp_path, text: str, name: str = 'hostile.yaml') -> str:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        load_scenario(str(path))
    message = str(error.value)
    assert message.startswith(f'{path}: '), message
    return message


@pytest.mark.timeout(60)
@pytest.mark.parametrize('nesting', ['[' * 5000 + ']' * 5000, '{a: ' * 5000 + '1' + '}' * 5000])
def test_5000_deep_nesting_is_refused_naming_the_field(tmp_path, nesting):
    message = refused(tmp_path, with_field('description', ' ' + nesting))
    assert re.search(rf': description(\[0\]|\.a)+\.\.\..*: nested deeper than {MAX_DEPTH} levels '
                     rf'\(line {len(SHORT_LINE.splitlines())}, column \d+\)$', message), message


@pytest.mark.timeout(60)
def test_deep_block_nesting_is_refused(tmp_path):
    # 5000 levels of indentation would be a file of 25 MB: 500 (a quarter of a megabyte)
    block = ''.join(f'\n{" " * (i + 1)}k{i}:' for i in range(500)) + ' 1'
    message = refused(tmp_path, with_field('plant', block))
    assert message.startswith(f'{tmp_path}/hostile.yaml: plant.k0.k1...k59.k60.k61: ')
    assert f'nested deeper than {MAX_DEPTH} levels (line ' in message


@pytest.mark.timeout(60)
@pytest.mark.parametrize('field', ['description', 'name'])
def test_an_alias_bomb_is_refused_at_once(tmp_path, field):
    message = refused(tmp_path, with_field(field, '\n' + alias_bomb()))
    assert f'{field}[6]: its aliases expand it beyond' in message and 'alias bomb' in message


def test_an_alias_bomb_of_long_text_is_refused(tmp_path):
    # few nodes, but each alias repeats a long text: what an error message's repr would copy
    text = 'x' * 100_000
    items = ', '.join(['*t'] * 100)
    message = refused(tmp_path, with_field('description', f' [&t {text}, {items}]'))
    assert 'description: its aliases expand it beyond' in message


def test_a_document_that_contains_itself_is_refused(tmp_path):
    message = refused(tmp_path, with_field('description', ' &d [a, [b, *d]]'))
    assert 'description[1][1]: the alias *d is inside the node it refers to' in message


def test_aliases_within_the_limits_still_work(tmp_path):
    path = tmp_path / 'aliases.yaml'
    path.write_text(SHORT_LINE.replace('name: short_line\ndescription',
                                       'name: &n short_line\ndescription')
                    .replace('  name: short_line', '  name: *n'))
    assert load_scenario(str(path)).line.name == 'short_line'


def test_a_top_level_key_given_twice_is_refused(tmp_path):
    message = refused(tmp_path, SHORT_LINE + 'name: other\n')
    assert "the key 'name' is given twice, at line 5, column 1 and line " in message


@pytest.mark.parametrize('original, twice, field', [
    ('  length_m: 36000\n', '  length_m: 36000\n  length_m: 3600\n', 'line'),
    ('{name: Midway, position_m: 14000, dwell_s: 30}',
     '{name: Midway, position_m: 14000, dwell_s: 30, position_m: 15000}', 'line.stations[1]'),
    ('  max_jerk_mps3: 0.1\n', '  max_jerk_mps3: 0.1\n  max_jerk_mps3: 0.2\n', 'planning')])
def test_a_nested_key_given_twice_is_refused_naming_the_mapping(tmp_path, original, twice, field):
    assert original in SHORT_LINE
    message = refused(tmp_path, SHORT_LINE.replace(original, twice))
    key = twice.split(':')[-2].split()[-1].strip('{, ')
    assert f'{field}: the key {key!r} is given twice' in message


def test_a_tunnel_past_the_end_of_the_line_is_refused(tmp_path):
    original = '    - {start_m: 30000, length_m: 2000}'
    assert original in SHORT_LINE
    message = refused(tmp_path, SHORT_LINE.replace(original, '    - {start_m: 35000, '
                                                             'length_m: 2000}'))
    assert message.endswith('line.tunnels[0].length_m: the tunnel ends at 37000 m, past the end '
                            'of the line (36000 m)')


@pytest.mark.timeout(60)
def test_a_failure_injected_at_run_time_is_read_with_the_same_limits():
    # ros2 param set ... inject_failure: YAML text a peer sends to the running plant
    train = load_scenario('mao_2017_modes').train
    for text, words in [('{actuator: motor_1, kind: loss, actuator: motor_2}',
                         "the key 'actuator' is given twice"),
                        ('\n' + alias_bomb(), 'its aliases expand it beyond'),
                        ('[' * 5000 + ']' * 5000, 'nested deeper than')]:
        with pytest.raises(ConfigError, match=f'^inject_failure: .*{words}'):
            parse_failure_injection(text, train.actuator_names, 0.0)


def test_a_file_larger_than_the_limit_is_not_read(tmp_path, monkeypatch):
    monkeypatch.setattr(files, 'MAX_YAML_BYTES', 1000)
    message = refused(tmp_path, SHORT_LINE)
    assert message.endswith('larger than the limit of 1000 bytes')


def test_ttobench_json_with_a_key_given_twice_is_refused_naming_the_field(tmp_path):
    path = tmp_path / 'train.json'
    text = json.dumps(TRAIN)
    path.write_text(text.replace('"metadata": {', '"metadata": {"id": "twice", ', 1))
    with pytest.raises(ConfigError, match=rf"^{path}: metadata: the key 'id' is given twice$"):
        load_train(path)
    path.write_text(text[:-1] + ', "metadata": {}}')
    with pytest.raises(ConfigError, match=rf"^{path}: the key 'metadata' is given twice$"):
        load_train(path)


@pytest.mark.parametrize('depth', [MAX_DEPTH + 1, 5000])
def test_ttobench_json_nested_too_deep_is_refused(tmp_path, depth):
    path = tmp_path / 'track.json'
    deep = dict(TRACK, metadata=json.loads('[' * depth + ']' * depth) if depth < 500 else None)
    text = json.dumps(deep)
    if depth >= 500:
        text = text.replace('"metadata": null', '"metadata": ' + '[' * depth + ']' * depth)
    path.write_text(text)
    with pytest.raises(ConfigError, match=f'nested deeper than {MAX_DEPTH} levels'):
        load_track(path, 0.0)


def test_every_yaml_and_json_limit_names_the_file(tmp_path):
    path = tmp_path / 'a.json'
    path.write_text('{"a": [1, 2], "b": {"c": 1, "c": 2}}')
    with pytest.raises(ConfigError, match=rf"^{path}: b: the key 'c' is given twice$"):
        load_json(path)
    path = tmp_path / 'a.yaml'
    path.write_bytes(b'a: \xff\n')
    with pytest.raises(ConfigError, match=rf'^{path}: cannot read: .*utf-8'):
        load_yaml(path)
    with pytest.raises(ConfigError, match=rf'^{tmp_path}: not a readable file'):
        load_yaml(tmp_path)
    for text, words in [('a: 2001-02-30', 'day is out of range'),
                        ('a: ' + '1' * 5000, 'Exceeds the limit'),
                        ('a: !!python/object:os.system x', 'could not determine a constructor'),
                        ('a: *nowhere', 'undefined alias')]:
        with pytest.raises(ConfigError, match=f'^x.yaml: not valid YAML: .*{words}'):
            load_yaml_text(text, 'x.yaml')


# --- any bytes at all ---------------------------------------------------------------------------

YAML_ALPHABET = st.sampled_from(list('[]{}:-,&*!|>?#\'"\n ') + ['  ', 'a', 'x', '0', '1.5', '~',
                                                                   '<<', '&a', '*a', '!!str',
                                                                   'name', 'line', 'e9'])


@st.composite
def mutated_scenarios(draw) -> bytes:
    """short_line with a random stretch replaced by YAML-ish tokens: mostly a document that
    parses, with a hostile structure somewhere in it."""
    text = SHORT_LINE
    start = draw(st.integers(0, len(text)))
    end = draw(st.integers(start, min(len(text), start + 40)))
    middle = ''.join(draw(st.lists(YAML_ALPHABET, max_size=30)))
    return (text[:start] + middle + text[end:]).encode()


def loads_or_refuses(tmp_path_factory, data: bytes) -> None:
    path = tmp_path_factory.mktemp('any') / 'scenario.yaml'
    path.write_bytes(data)
    try:
        assert isinstance(load_scenario(str(path)), Scenario)
    except ConfigError as error:
        assert str(error).startswith(f'{path}: '), error


# Bounded inputs and no deadline: a hang is caught by the test's timeout, not by a timed assert.
PROPERTY = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.mark.timeout(300)
@PROPERTY
@given(data=st.binary(max_size=512))
def test_any_bytes_give_a_scenario_or_a_config_error(tmp_path_factory, data):
    loads_or_refuses(tmp_path_factory, data)


@pytest.mark.timeout(300)
@PROPERTY
@given(data=mutated_scenarios())
def test_any_damage_to_a_scenario_gives_a_scenario_or_a_config_error(tmp_path_factory, data):
    loads_or_refuses(tmp_path_factory, data)


def _paths(data, prefix=()):
    """Every path into a loaded document (mapping keys and list positions)."""
    yield prefix
    items = data.items() if isinstance(data, dict) else (
        enumerate(data) if isinstance(data, list) else ())
    for key, value in items:
        yield from _paths(value, (*prefix, key))


YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda children: st.lists(children, max_size=3)
    | st.dictionaries(st.text(max_size=6), children, max_size=3),
    max_leaves=8)
SHORT_LINE_PATHS = list(_paths(files.load_yaml_text(SHORT_LINE, 'short_line')))


@st.composite
def scenarios_with_a_field_replaced(draw) -> bytes:
    """short_line with one field (or list item, or section) replaced by any YAML value."""
    data = files.load_yaml_text(SHORT_LINE, 'short_line')
    path = draw(st.sampled_from(SHORT_LINE_PATHS[1:]))
    parent = data
    for key in path[:-1]:
        parent = parent[key]
    parent[path[-1]] = draw(YAML_VALUES)
    return yaml.safe_dump(data, allow_unicode=True).encode()


@pytest.mark.timeout(300)
@PROPERTY
@given(data=scenarios_with_a_field_replaced())
def test_any_value_in_any_field_gives_a_scenario_or_a_config_error(tmp_path_factory, data):
    loads_or_refuses(tmp_path_factory, data)


@pytest.mark.timeout(300)
@PROPERTY
@given(data=st.binary(max_size=512) | st.text(alphabet='[]{}":,0123456789.eE-truefalsn \\',
                                               max_size=512).map(str.encode))
def test_any_bytes_give_json_data_or_a_config_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp('any') / 'track.json'
    path.write_bytes(data)
    try:
        load_json(path)
    except ConfigError as error:
        assert str(error).startswith(f'{path}: '), error
