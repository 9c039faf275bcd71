"""The scorecard (issue 32): the minimal ATO node written from the contract page runs a small
campaign's draws through the ROS graph to the end, its rows computed by the campaign's own
metrics beside the built-in laws' rows on the same draws, with the paired comparison against the
baseline; the deliberately broken node's runs are failing rows, not a crash.

The campaign: the 3 km leg with a grade of the row rerun's test, with the speed sensor failed
for 4 s at cruise (the contract: a NaN measurement, and still a finite command), one law, two
draws of the default uncertainty."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from test_campaign_row_graph import LINE

from ato_bringup import scorecard
from ato_campaigns.dataset import file_description, read_rows, rows_folder
from ato_campaigns.engine import METRICS, load_campaign
from ato_common.run_events import MEASURED

pytestmark = pytest.mark.integration

EXAMPLES = Path(__file__).resolve().parents[1] / 'examples' / 'external_ato'
SENSOR_FAILURE = """plant:
  sensors:
    speed: {failed_from_s: 60, failed_until_s: 64}
"""
CAMPAIGN = """name: score
seed: 3
draws: 2
scenarios: [line.yaml]
laws: [pid]
configurations: [published]
timeout_s: 600
"""


@pytest.fixture
def campaign_path(tmp_path) -> Path:
    (tmp_path / 'line.yaml').write_text(LINE + SENSOR_FAILURE)
    path = tmp_path / 'score.yaml'
    path.write_text(CAMPAIGN)
    return path


def run_scorecard(node: str, label: str, campaign_path: Path, out: Path):
    command = f'{sys.executable} {EXAMPLES / node}'
    return command, subprocess.run(
        [sys.executable, '-m', 'ato_bringup.scorecard', '--controller-command', command,
         '--campaign', str(campaign_path), '--label', label, '--out', str(out)],
        capture_output=True, text=True, timeout=1500)


def test_the_minimal_node_runs_the_scorecard_to_the_end_beside_the_built_in_law(
        campaign_path, tmp_path):
    out = tmp_path / 'out'
    command, done = run_scorecard('p_ato_node.py', 'p_example', campaign_path, out)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    campaign = load_campaign(campaign_path)
    mine = read_rows(rows_folder(out, 'score-scorecard-p_example'), campaign.fingerprint)
    # every draw, run to the end of its journey, judged by the campaign's own rules
    assert list(mine['draw']) == [0, 1] and set(mine['law']) == {'p_example/own'}
    assert mine['status'].isin(MEASURED).all(), mine[['status', 'reason']]
    assert mine['status'].isin(['ok', 'stop error', 'late']).all(), mine[['status', 'reason']]
    assert set(METRICS) <= set(mine.columns)
    assert mine['traction_energy_kwh'].gt(0).all() and mine['stop_error_m'].lt(50).all()
    assert mine['saturated_fraction'].isna().all()  # not on the wire for an external node
    assert mine['watchdog_events'].eq(0).all()  # finite commands through the failed sensor
    # the same draws as the built-in law's: the same truth
    builtin = read_rows(rows_folder(out, 'score'), campaign.fingerprint)
    assert list(builtin['draw']) == [0, 1]
    assert (mine['p_mass_factor'].to_list() == builtin['p_mass_factor'].to_list())
    # the contract's knowledge parameter was given to the node, as drawn
    assert set(mine['p_gradient_known']) == set(builtin['p_gradient_known'])
    folder = out / 'score-scorecard-p_example'
    assert (scorecard.through(command) ==
            file_description(next((folder / 'rows').glob('*.parquet')))['through'])
    logs = list((folder / 'graph').glob('p_example-own-draw*/controller.log'))
    assert len(logs) == 2
    assert 'gradient_known=' in logs[0].read_text()
    # the scorecard: both laws, the KPIs, the paired comparison with the baseline
    assert 'pid/published' in done.stdout and 'p_example/own' in done.stdout
    assert 'p_example/own - pid/published, stop_error_m: mean' in done.stdout
    report = (folder / 'report.md').read_text()
    assert 'p_example/own' in report and scorecard.through(command) in report


def test_the_broken_node_gives_failing_rows_not_a_crash(campaign_path, tmp_path):
    """It passes the failed sensor's NaN into its law: its commands are rejected and the
    plant's watchdog brakes; the scorecard still ends, with those rows failing."""
    out = tmp_path / 'out'
    _, done = run_scorecard('broken_ato_node.py', 'broken', campaign_path, out)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output  # every run finished with metrics
    rows = read_rows(rows_folder(out, 'score-scorecard-broken'),
                     load_campaign(campaign_path).fingerprint)
    assert list(rows['draw']) == [0, 1]
    # failing rows: the watchdog's brakes named (and the ATP's, which come first, if any)
    assert rows['status'].isin(['watchdog brake', 'ATP intervention']).all(), rows['status']
    assert rows['reason'].str.contains('watchdog brakes').all(), rows['reason']
    assert rows['watchdog_events'].gt(0).all()
    assert 'broken/own' in done.stdout and 'watchdog brake' in done.stdout


def test_a_node_that_cannot_run_gives_error_rows_with_the_reason(campaign_path, tmp_path):
    """A node that exits at once: each run is a row with status error and why, the scorecard
    ends and exits 1."""
    out = tmp_path / 'out'
    command = f'{sys.executable} -c "import sys; sys.exit(3)"'
    done = subprocess.run(
        [sys.executable, '-m', 'ato_bringup.scorecard', '--controller-command', command,
         '--campaign', str(campaign_path), '--label', 'gone', '--out', str(out)],
        capture_output=True, text=True, timeout=900)
    output = done.stdout + done.stderr
    assert done.returncode == 1, output
    rows = read_rows(rows_folder(out, 'score-scorecard-gone'),
                     load_campaign(campaign_path).fingerprint)
    assert list(rows['status']) == ['error', 'error'], rows['reason']
    assert rows['reason'].str.contains('the run through the graph failed: controller exited '
                                       'with code 3').all(), rows['reason']
    assert 'failed: gone/own draw 0: the run through the graph failed' in done.stdout
    assert '0 of 2 runs' in done.stderr
