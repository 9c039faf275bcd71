"""The walk-throughs of docs/extending.md work as written: its code blocks are run here."""

import re
from pathlib import Path

import pytest
import yaml

from ato_common import conventions, trains
from ato_common.scenario import load_scenario, parse_scenario
from ato_controller_node import host, laws, node
from ato_simulation.loop import run_offline
from ato_tools import reference_pages

PAGE = (Path(__file__).resolve().parents[2] / 'docs/extending.md').read_text()


def _blocks(language: str) -> list[str]:
    blocks = re.findall(rf'^( *)```{language}\n(.*?)^\1```', PAGE, flags=re.S | re.M)
    return ['\n'.join(line[len(indent):] for line in body.splitlines())
            for indent, body in blocks]


def test_the_page_has_the_four_walk_throughs():
    assert len(_blocks('python')) == 3 and len(_blocks('yaml')) == 1
    for heading in ('Add a control law', 'Add a train preset', 'Add a scenario', 'Add a topic'):
        assert f'\n## {heading}\n' in PAGE


@pytest.fixture
def example_law(monkeypatch):
    namespace = {}
    exec(_blocks('python')[0], namespace)  # noqa: S102 - the page's own example
    law = namespace['PdExampleLaw']
    registry = dict(laws.LAWS, **{law.name: law})
    for module in (laws, host, node):
        monkeypatch.setattr(module, 'LAWS', registry, raising=False)
    monkeypatch.setattr(reference_pages, 'LAWS', registry)
    return law


def test_the_example_law_registers_drives_the_train_and_declares_its_gains(example_law):
    run = run_offline(load_scenario('short_line'), example_law.name, end_time_s=300.0)
    errors = run.ref_speeds - run.speeds
    assert abs(errors).max() < 1.0, 'the example law tracks the reference within 1 m/s'
    names = {p.name for p in node.gain_params()}
    assert {'pd_example.kp_position', 'pd_example.kd_speed'} <= names
    assert '\n## pd_example\n' in reference_pages.laws_page()


def test_the_example_preset_loads_in_a_scenario(monkeypatch):
    namespace = {}
    exec(_blocks('python')[1], namespace)  # noqa: S102
    monkeypatch.setitem(trains.TRAIN_PRESETS, 'example_8car', namespace['_example_8car'])
    data = yaml.safe_load(_blocks('yaml')[0])
    data['train'] = {'preset': 'example_8car'}
    scenario = parse_scenario(data, 'extending.md')
    assert scenario.train.mass_kg == pytest.approx(420e3)
    assert '\n## example_8car\n' in reference_pages.trains_page()


def test_the_example_scenario_parses_and_runs():
    scenario = parse_scenario(yaml.safe_load(_blocks('yaml')[0]), 'extending.md')
    assert [s.name for s in scenario.line.stations] == ['Origin', 'Middle', 'Terminus']
    run = run_offline(scenario, 'pid', end_time_s=120.0)
    assert run.speeds[-1] > 10.0


def test_the_example_topic_appears_on_the_topics_page(monkeypatch):
    namespace = {}
    exec(_blocks('python')[2], namespace)  # noqa: S102
    monkeypatch.setitem(conventions.TOPICS, 'example', namespace['TOPIC'])
    monkeypatch.setattr(reference_pages, 'TOPICS', conventions.TOPICS)
    assert '| `ato/example` | `std_msgs/msg/Float64` |' in reference_pages.topics_page()
