"""Hostile files given to the tools (issue 29, item 5): run_scenario, run_offline, a campaign and
each node at start refuse a 5000-deep nesting, an alias bomb and a key given twice with exit
status 2 and a message naming the file and the field, at once, with no traceback."""

import os
import subprocess
from importlib import resources

import pytest

from ato_bringup import run_scenario
from ato_bringup.stack import EXECUTABLES, executable_path
from ato_campaigns import campaign
from ato_common.files import MAX_DEPTH
from ato_simulation import run_offline

SHORT_LINE = (resources.files('ato_common') / 'scenarios' / 'short_line.yaml').read_text()
BOMB = '\n'.join(['  - &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]'] + [
    f'  - &l{i} [' + ', '.join([f'*l{i - 1}'] * 9) + ']' for i in range(1, 9)])
HOSTILE = {
    # (what replaces the scenario's name, what the error says)
    'deep': (' ' + '[' * 5000 + ']' * 5000, f'nested deeper than {MAX_DEPTH} levels'),
    'bomb': ('\n' + BOMB, 'its aliases expand it beyond'),
}


def hostile_scenario(tmp_path, kind: str):
    value, words = HOSTILE[kind]
    path = tmp_path / f'{kind}.yaml'
    path.write_text(SHORT_LINE.replace('name: short_line\n', f'name:{value}\n', 1))
    return path, f'{path}: name', words


def refused_at_once(capsys, code: int, path, words: str) -> None:
    err = capsys.readouterr().err
    assert code == 2, err
    assert f'error: {path}: name' in err and words in err, err
    assert 'Traceback' not in err


@pytest.mark.timeout(120)
@pytest.mark.parametrize('kind', sorted(HOSTILE))
def test_run_offline_refuses_a_hostile_scenario(tmp_path, capsys, kind):
    path, _, words = hostile_scenario(tmp_path, kind)
    refused_at_once(capsys, run_offline.main(['--scenario', str(path)]), path, words)


@pytest.mark.timeout(120)
@pytest.mark.parametrize('kind', sorted(HOSTILE))
def test_run_scenario_refuses_a_hostile_scenario_before_starting_a_node(tmp_path, capsys, kind):
    path, _, words = hostile_scenario(tmp_path, kind)
    code = run_scenario.main(['--scenario', str(path), '--log-dir', str(tmp_path / 'run')])
    refused_at_once(capsys, code, path, words)
    assert not list((tmp_path / 'run').glob('*.log'))  # no node was started


@pytest.mark.timeout(120)
@pytest.mark.parametrize('kind', sorted(HOSTILE))
def test_a_campaign_refuses_a_hostile_scenario_and_a_hostile_campaign_file(tmp_path, capsys,
                                                                         kind):
    path, _, words = hostile_scenario(tmp_path, kind)
    plan = tmp_path / 'campaign.yaml'
    plan.write_text(f'name: hostile\ndraws: 2\nscenarios: [{path}]\nlaws: [pid]\n')
    code = campaign.main([str(plan), '--serial', '--out', str(tmp_path / 'out')])
    err = capsys.readouterr().err
    assert code == 2 and f'scenarios[0]: {path}: name' in err and words in err, err
    assert 'Traceback' not in err
    value = HOSTILE[kind][0]
    plan.write_text(f'name:{value}\ndraws: 2\nscenarios: [short_line]\nlaws: [pid]\n')
    code = campaign.main([str(plan), '--serial', '--out', str(tmp_path / 'out')])
    refused_at_once(capsys, code, plan, words)
    plan.write_text('name: twice\ndraws: 2\nscenarios: [short_line]\nlaws: [pid]\ndraws: 3\n')
    code = campaign.main([str(plan), '--serial', '--out', str(tmp_path / 'out')])
    err = capsys.readouterr().err
    assert code == 2 and f"{plan}: the key 'draws' is given twice" in err, err


@pytest.mark.timeout(120)
@pytest.mark.parametrize('name', ['plant', 'profile', 'controller'])
def test_a_node_refuses_a_hostile_scenario_at_start(tmp_path, name, domain_id):
    for kind in sorted(HOSTILE):
        path, field, words = hostile_scenario(tmp_path, kind)
        result = subprocess.run([executable_path(*EXECUTABLES[name]), '--ros-args', '-p',
                                 f'scenario:={path}'], capture_output=True, text=True,
                                timeout=60, env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
        assert result.returncode == 2, result.stderr
        assert f'error: {field}' in result.stderr and words in result.stderr, result.stderr
        assert 'Traceback' not in result.stderr


@pytest.mark.timeout(120)
def test_a_node_refuses_a_hostile_parameters_file_at_start(tmp_path, domain_id):
    """rcl reads a parameters file itself: it would keep the last of a key given twice, and a
    YAML alias made rclpy raise a traceback."""
    files = {
        'twice': ('/**:\n  ros__parameters:\n    rate_hz: 5.0\n    rate_hz: 7.0\n',
                  "ros__parameters: the key 'rate_hz' is given twice"),
        'deep': ('/**:\n  ros__parameters:\n    a: ' + '[' * 5000 + ']' * 5000 + '\n',
                 f'nested deeper than {MAX_DEPTH} levels'),
        'alias': ('/**:\n  ros__parameters:\n    a: &a 1.0\n    rate_hz: *a\n',
                  'Will not support aliasing'),
    }
    for kind, (text, words) in files.items():
        path = tmp_path / f'{kind}.yaml'
        path.write_text(text)
        result = subprocess.run([executable_path(*EXECUTABLES['controller']), '--ros-args',
                                 '--params-file', str(path)], capture_output=True, text=True,
                                timeout=60, env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
        assert result.returncode == 2, (kind, result.stderr)
        assert str(path) in result.stderr and words in result.stderr, result.stderr
        assert 'Traceback' not in result.stderr
