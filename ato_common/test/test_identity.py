"""The identity of a scenario (what the plant publishes, what the plan cache keys by): equal for
equal content wherever it was read from, different for any difference a run could show,
including the braking data held in the supervision's deceleration functions."""

import dataclasses
import shutil
from importlib import resources

import pytest

from ato_common.braking_curves import constant_deceleration
from ato_common.identity import (
    identity_mismatch,
    parse_identity,
    scenario_hash,
    scenario_identity,
)
from ato_common.scenario import builtin_scenarios, load_scenario


def test_the_same_scenario_has_the_same_identity_wherever_it_was_read_from(tmp_path):
    first = load_scenario('short_line')
    path = tmp_path / 'copy.yaml'
    shutil.copy(resources.files('ato_common') / 'scenarios' / 'short_line.yaml', path)
    copy = load_scenario(str(path))
    assert first.origin != copy.origin
    assert scenario_hash(first) == scenario_hash(copy)
    assert identity_mismatch(scenario_identity(first), scenario_identity(copy)) == ''


def test_a_different_braking_deceleration_is_a_different_scenario():
    scenario = load_scenario('short_line')
    supervision = scenario.supervision
    value = supervision.emergency_deceleration(0.0)
    other = dataclasses.replace(scenario, supervision=dataclasses.replace(
        supervision, emergency_deceleration=constant_deceleration(value * 0.9)))
    same = dataclasses.replace(scenario, supervision=dataclasses.replace(
        supervision, emergency_deceleration=constant_deceleration(value)))
    assert scenario_hash(other) != scenario_hash(scenario)
    assert scenario_hash(same) == scenario_hash(scenario)
    why = identity_mismatch(scenario_identity(scenario), scenario_identity(other))
    assert 'same name, different content' in why and 'short_line' in why


def test_every_builtin_scenario_has_an_identity_of_its_own():
    hashes = {name: scenario_hash(load_scenario(name)) for name in builtin_scenarios()}
    assert len(set(hashes.values())) == len(hashes)


def test_an_identity_that_is_not_one_is_refused_naming_what_is_wrong():
    with pytest.raises(ValueError, match='not JSON'):
        parse_identity('scenario short_line')
    with pytest.raises(ValueError, match='needs the strings scenario, sha256'):
        parse_identity('{"scenario": "short_line"}')
