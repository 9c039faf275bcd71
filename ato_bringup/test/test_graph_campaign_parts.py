"""The parts of a campaign made through the graph (ato_bringup.graph_campaign) that need no
graph: the arguments, a row whose graph run failed (an error row with its reason), the rows'
folder and format, the per-row verdict and the comparison table, and the campaign command's
hand-over."""

import math

import pytest
import yaml

from ato_bringup import graph_campaign
from ato_bringup.graph_campaign import comparison_table, run_row, verdict
from ato_bringup.runner import RunFailed
from ato_campaigns import campaign as campaign_command
from ato_campaigns.dataset import file_description, read_rows, rows_folder
from ato_campaigns.engine import METRICS, base_row, load_campaign

CAMPAIGN = {'name': 'graph_parts', 'seed': 3, 'draws': 2, 'scenarios': ['short_line'],
            'laws': ['pid'], 'configurations': ['published'], 'end_time_s': 20,
            'timeout_s': 60}


@pytest.fixture
def campaign_path(tmp_path):
    path = tmp_path / 'parts.yaml'
    path.write_text(yaml.safe_dump(CAMPAIGN))
    return path


def test_workers_default_to_one_and_fewer_than_one_is_refused(capsys):
    args = graph_campaign.parse_args(['c.yaml'])
    assert args.workers == 1
    with pytest.raises(SystemExit) as exit_:
        graph_campaign.parse_args(['c.yaml', '--workers', '0'])
    assert exit_.value.code == 2
    assert '--workers: at least 1, got 0' in capsys.readouterr().err
    assert graph_campaign.main(['no_such_campaign.yaml']) == 2


def _killed(task, run, runs, timeout_s=None):
    raise RunFailed('controller exited with SIGKILL at simulated 3.0 s of 20.0 s: the run is '
                    'stopped.')


def test_a_killed_graph_run_is_an_error_row_with_its_reason(campaign_path, monkeypatch, tmp_path):
    monkeypatch.setattr(graph_campaign, 'graph_row_of', _killed)
    campaign = load_campaign(campaign_path)
    result = run_row((campaign, campaign.tasks()[0], tmp_path / 'graph'))
    graph = result['graph']
    assert graph['status'] == 'error'
    assert graph['reason'] == ('the run through the graph failed: controller exited with '
                               'SIGKILL at simulated 3.0 s of 20.0 s: the run is stopped.')
    assert all(math.isnan(graph[k]) for k in METRICS) and graph['wall_s'] >= 0
    assert result['offline']['status'] in ('ok', 'did not finish')  # made offline all the same
    ok, words = verdict(result)
    assert not ok and words.startswith('the run through the graph failed: controller exited')


def test_any_other_failure_of_a_graph_run_is_an_error_row_naming_the_exception(
        campaign_path, monkeypatch, tmp_path):
    def broken(*args, **kwargs):
        raise OSError('no space left on device')
    monkeypatch.setattr(graph_campaign, 'graph_row_of', broken)
    campaign = load_campaign(campaign_path)
    graph = run_row((campaign, campaign.tasks()[0], tmp_path))['graph']
    assert graph['status'] == 'error'
    assert 'OSError: no space left on device' in graph['reason']


def _row(task, **changes):
    return {**base_row(task), 'status': 'ok', 'reason': '', **dict.fromkeys(METRICS, 1.0),
            **changes}


def test_the_table_says_per_row_whether_it_is_identical_and_counts_them(campaign_path):
    tasks = load_campaign(campaign_path).tasks()
    same = {'offline': _row(tasks[0]), 'graph': _row(tasks[0], stop_error_m=1.0 + 1e-12),
            'notes': []}
    differs = {'offline': _row(tasks[1]), 'graph': _row(tasks[1], stop_error_m=1.1,
                                                         status='stop error'), 'notes': []}
    lost = graph_campaign.lost_row((None, tasks[1], None), 'the cluster lost the run')
    assert verdict(same) == (True, 'identical')
    assert verdict(differs) == (False, 'differs in status, stop_error_m')
    assert verdict(lost) == (False, 'no offline row; graph: the cluster lost the run')
    table, count = comparison_table([differs, same])
    assert count == 1
    lines = table.splitlines()
    assert lines[0].split() == ['scenario', 'law', 'draw', 'offline', 'graph', 'verdict']
    assert lines[1].split()[:3] == ['short_line', 'pid/published', '0']  # sorted by draw
    assert lines[1].endswith('identical') and lines[2].endswith('differs in status, '
                                                                 'stop_error_m')
    assert lines[-1].startswith('1 of 2 rows identical')


def test_the_graph_rows_go_to_their_own_folder_in_the_campaign_s_format(
        campaign_path, monkeypatch, tmp_path, capsys):
    def made(item):
        return {'offline': _row(item[1]), 'graph': _row(item[1]), 'notes': []}
    monkeypatch.setattr(graph_campaign, 'run_row', made)
    campaign = load_campaign(campaign_path)
    results = graph_campaign.run_graph_campaign(campaign, tmp_path)
    assert len(results) == 2
    folder = rows_folder(tmp_path, 'graph_parts-ros')
    rows = read_rows(folder, campaign.fingerprint)
    assert list(rows['draw']) == [0, 1] and set(METRICS) <= set(rows.columns)
    files = list(folder.glob('*.parquet'))
    assert len(files) == 1  # merged once complete, as the campaign does
    assert file_description(files[0])['through'] == graph_campaign.THROUGH
    assert '2/2 pid/published draw 1: ok through the graph, identical' in capsys.readouterr().err


def test_a_folder_of_another_version_of_the_campaign_is_refused(campaign_path, monkeypatch,
                                                                tmp_path, capsys):
    monkeypatch.setattr(graph_campaign, 'run_row', lambda item: pytest.fail('ran'))
    other = dict(base_row(load_campaign(campaign_path).tasks()[0]), fingerprint='0' * 16)
    from ato_campaigns.dataset import write_row
    write_row(rows_folder(tmp_path, 'graph_parts-ros'), other)
    assert graph_campaign.main([str(campaign_path), '--out', str(tmp_path)]) == 2
    assert 'holds the rows of another version' in capsys.readouterr().err


def test_the_campaign_command_hands_a_campaign_through_ros_to_graph_campaign(
        campaign_path, monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(campaign_command.subprocess, 'call', lambda command: calls.append(
        command) or 0)
    assert campaign_command.main([str(campaign_path), '--through', 'ros', '--workers', '2',
                                  '--out', str(tmp_path)]) == 0
    assert calls[0][1:] == ['-m', 'ato_bringup.graph_campaign', str(campaign_path), '--out',
                            str(tmp_path), '--workers', '2']
    assert campaign_command.main([str(campaign_path), '--through', 'ros']) == 0
    assert '--workers' not in calls[1]  # graph_campaign's default: one at a time
    for offline_only in ('--serial', '--scheduler=tcp://h:8786', '--readme=README.md'):
        with pytest.raises(SystemExit):
            campaign_command.parse_args([str(campaign_path), '--through', 'ros', offline_only])
