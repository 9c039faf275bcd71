"""The shipped Foxglove layout plots the suite's topics, and its force panel compares like with
like: per actuator, the commanded and the applied force of the same actuator topic layout."""

import json
import re
from pathlib import Path

from ato_common.conventions import TOPICS

LAYOUT = Path(__file__).parents[1] / 'config' / 'foxglove_layout.json'
PATH = re.compile(r'^(/[\w/]+)\.(.+)$')


def panels():
    return json.loads(LAYOUT.read_text())['configById']


def topic_names():
    return {'/' + t.name.lstrip('/') for t in TOPICS.values()}


def test_every_plotted_path_is_a_topic_of_the_suite():
    for panel, config in panels().items():
        for path in config.get('paths', []):
            match = PATH.match(path['value'])
            assert match and match.group(1) in topic_names(), (panel, path['value'])


def test_the_force_panel_pairs_commanded_and_applied_per_actuator():
    paths = [p['value'] for p in panels()['Plot!force']['paths']]
    commanded = '/' + TOPICS['actuators_commanded'].name
    applied = '/' + TOPICS['actuators_applied'].name
    fields = {}
    for value in paths:
        topic, field = PATH.match(value).groups()
        assert topic in (commanded, applied), value
        fields.setdefault(field, set()).add(topic)
    assert fields and all(topics == {commanded, applied} for topics in fields.values()), fields
