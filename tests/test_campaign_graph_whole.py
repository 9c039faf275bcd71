"""A whole campaign made through the ROS graph (issue 32): every row of a small campaign (one 3 km
leg with a grade, two laws, draws of the default uncertainty) through the nodes in lockstep,
each in a DDS domain of its own, gives the rows made offline (``ato_bringup.graph_campaign``);
the graph's rows are in the campaign's row format and its report is made on them; a graph run
that cannot finish becomes a row with status ``error`` and its reason, never a hang.

The first test is the acceptance's campaign: 2 laws x 4 draws (8 graph runs of about 170 s of
simulated time each), two at a time on a Dask LocalCluster of 2 workers, each run in a DDS domain
of its own."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from test_campaign_row_graph import LINE  # the 3 km leg with a grade of the row rerun's test

from ato_bringup import graph_campaign
from ato_campaigns.dataset import file_description, read_rows, rows_folder
from ato_campaigns.engine import METRICS, load_campaign

pytestmark = pytest.mark.integration

CAMPAIGN = """name: {name}
seed: 5
draws: {draws}
scenarios: [line.yaml]
laws:
  - {{law: pid, label: pid_flat, gradient: hidden, settings: {{kp_position: 0.3}}}}
  - {{law: pid}}
configurations: [published]
timeout_s: {timeout}
"""


def campaign_file(folder, name: str, draws: int, timeout: float):
    (folder / 'line.yaml').write_text(LINE)
    path = folder / f'{name}.yaml'
    path.write_text(CAMPAIGN.format(name=name, draws=draws, timeout=timeout))
    return path


def test_every_row_of_a_campaign_through_the_graph_is_the_offline_row(tmp_path):
    """The command a user types: the campaign command hands the campaign to graph_campaign."""
    path = campaign_file(tmp_path, 'graph_whole', draws=4, timeout=900)
    out = tmp_path / 'out'
    result = subprocess.run(
        [sys.executable, '-m', 'ato_campaigns.campaign', str(path), '--through', 'ros',
         '--workers', '2', '--out', str(out)], capture_output=True, text=True, timeout=1800)
    assert result.returncode == 0, result.stdout + result.stderr
    assert '8 of 8 rows identical offline and through the graph' in result.stdout
    assert '8 rows through the graph, 2 at once' in result.stderr  # the LocalCluster's 2 workers
    campaign = load_campaign(path)
    folder = rows_folder(out, 'graph_whole-ros')
    rows = read_rows(folder, campaign.fingerprint)
    assert sorted(zip(rows['law'], rows['draw'])) == [
        (law, draw) for law in ('pid/published', 'pid_flat/published') for draw in range(4)]
    assert set(METRICS) <= set(rows.columns)
    assert rows['status'].isin(['ok', 'stop error', 'late']).all()  # whole journeys
    assert rows['traction_energy_kwh'].gt(0).all() and rows['wall_s'].gt(0).all()
    description = file_description(next(folder.glob('*.parquet')))
    assert description['fingerprint'] == campaign.fingerprint
    assert description['through'] == graph_campaign.THROUGH
    report = json.loads((out / 'graph_whole-ros' / 'report.json').read_text())
    assert report  # the campaign's own report, made on the graph's rows
    assert set(rows['through']) == {graph_campaign.THROUGH}
    # the report names how its rows were made, from the rows
    text = (out / 'graph_whole-ros' / 'report.md').read_text()
    assert graph_campaign.THROUGH in text and 'offline closed loop' not in text


def test_a_graph_run_that_cannot_finish_is_an_error_row_with_its_reason(tmp_path):
    """The campaign's timeout_s bounds a graph run (the runner's own limit): past it the run is
    stopped, its row says why, and the command exits 1."""
    path = campaign_file(tmp_path, 'graph_late', draws=1, timeout=2)
    out = tmp_path / 'out'
    campaign = load_campaign(path)
    results = graph_campaign.run_graph_campaign(campaign, out)
    assert len(results) == 2
    for result in results:
        graph = result['graph']
        assert graph['status'] == 'error', graph
        assert 'the run through the graph failed' in graph['reason']
        assert 'did not end within 2 s of wall time' in graph['reason']
        assert result['offline']['status'] in ('ok', 'stop error', 'late')
        assert graph_campaign.verdict(result)[0] is False
    rows = read_rows(rows_folder(out, 'graph_late-ros'), campaign.fingerprint)
    assert list(rows['status']) == ['error', 'error']
    table, same = graph_campaign.comparison_table(results)
    assert same == 0 and '0 of 2 rows identical' in table
