"""Robustness campaigns (ato_campaigns.campaign): bad files refused before anything runs, common
random numbers, identical rows serially, on a 2-worker LocalCluster and on a cluster started with
the dask command line, resume, time limits and failures reported, and the statistics against
values computed by hand."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import socket
import subprocess
import sys
import time
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import pytest
import yaml

from ato_campaigns import dataset, engine
from ato_campaigns import stats as cs
from ato_campaigns.campaign import main
from ato_campaigns.dataset import FolderConflict
from ato_campaigns.engine import (
    METRICS,
    load_campaign,
    read_rows,
    rows_folder,
    run_campaign,
    run_task,
    unfinished,
)
from ato_common import uncertainty
from ato_common.run_events import LATE_AFTER_S
from ato_common.scenario import load_scenario, parse_scenario
from ato_common.validation import ConfigError
from ato_simulation.loop import run_offline

#: a tiny campaign: 2 laws x 1 scenario x 4 draws of the first 40 s of the short line, in
#: the published configuration (test_configurations.py runs both)
TINY = {'name': 'tiny', 'seed': 11, 'draws': 4, 'scenarios': ['short_line'],
        'laws': ['pid', {'law': 'luo_xu'}], 'configurations': ['published'], 'end_time_s': 40,
        'timeout_s': 120}
PID, LUO = 'pid/published', 'luo_xu/published'
#: columns that differ between two runs of the same campaign (wall time)
VOLATILE = ('wall_s',)


def write(tmp_path: Path, data: dict, name: str = 'campaign.yaml') -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def comparable(rows: pd.DataFrame) -> pd.DataFrame:
    return rows.drop(columns=list(VOLATILE)).sort_values(['scenario', 'law', 'draw']) \
        .reset_index(drop=True)


@pytest.mark.parametrize('change, field, words', [
    ({'uncertainty': {'wind_speed': 2}}, 'uncertainty.wind_speed', 'unknown parameter'),
    ({'uncertainty': {'mass_factor': {'dist': 'uniform', 'low': 1.1, 'high': 1.0}}},
     'uncertainty.mass_factor', 'must be above low'),
    ({'laws': ['pid', 'mao_2017']}, 'laws[1]', "mao_2017 does not fit scenario 'short_line'"),
    ({'laws': ['pid', 'pdi']}, 'laws[1]', "unknown law 'pdi'"),
    ({'laws': [{'law': 'pid', 'settings': {'kp_gain': 1}}]}, 'laws[0].settings.kp_gain',
     'not a setting of pid'),
    ({'scenarios': ['no_such_line']}, 'scenarios[0]', 'neither a built-in scenario'),
    ({'draws': 0}, 'draws', 'must be >= 1'),
    ({'baseline': 'tan_weighted_mm'}, 'baseline', 'not one of the campaign'),
    ({'seeds': 3}, 'the file', 'unknown field(s) seeds'),
    ({'draws': 2.5}, 'draws', 'must be a whole number, got 2.5'),
    ({'seed': 1.5}, 'seed', 'must be a whole number, got 1.5'),
    ({'uncertainty': {'mass_factor': {'dist': 'truncated_normal', 'mean': 1.5, 'std': 0.05,
                                      'low': 0.97, 'high': 1.2}}},
     'uncertainty.mass_factor.mean', '1.5 must lie within [low, high] = [0.97, 1.2]'),
])
def test_a_bad_campaign_names_the_file_and_the_field_before_anything_runs(
        tmp_path, capsys, change, field, words):
    path = write(tmp_path, {**TINY, **change})
    with pytest.raises(ConfigError) as error:
        load_campaign(path)
    assert str(path) in str(error.value) and field in str(error.value)
    assert words in str(error.value)
    assert main([str(path), '--serial', '--out', str(tmp_path / 'out')]) == 2
    assert field in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()  # nothing ran


def test_every_law_gets_the_same_plant_for_the_same_draw(tmp_path):
    campaign = load_campaign(write(tmp_path, TINY))
    tasks = campaign.tasks()
    assert len(tasks) == 8
    for index in range(4):
        values = [t['values'] for t in tasks if t['draw'] == index]
        assert len(values) == 2 and values[0] == values[1]
    assert tasks[0]['values'] != next(t for t in tasks if t['draw'] == 1)['values']
    assert load_campaign(write(tmp_path, TINY)).tasks() == tasks  # reproducible


@pytest.fixture(scope='module')
def serial_rows(tmp_path_factory):
    folder = tmp_path_factory.mktemp('serial')
    campaign = load_campaign(write(folder, TINY))
    rows = run_campaign(campaign, folder / 'out', serial=True, progress=False)
    return campaign, rows


def test_a_serial_campaign_has_one_row_per_run_with_its_draw_and_metrics(serial_rows):
    campaign, rows = serial_rows
    assert len(rows) == 8 and set(rows['status']) == {'ok'}
    assert set(rows['law']) == {PID, LUO} and sorted(set(rows['draw'])) == [0, 1, 2, 3]
    assert set(rows['configuration']) == {'published'} and set(rows['envelope']) == {True}
    for column in ('campaign', 'scenario', 'law', 'draw', 'status', 'reason', *METRICS):
        assert column in rows.columns
    for name in campaign.specs[campaign.scenarios[0]]:
        assert f'p_{name}' in rows.columns
    assert rows['p_mass_factor'].nunique() == 4  # one value per draw, shared by the laws
    assert np.all(np.isfinite(rows['rms_speed_error_kmh']))
    assert rows.groupby('draw')['rms_speed_error_kmh'].nunique().max() == 2


def test_a_two_worker_local_cluster_gives_the_serial_rows(serial_rows, tmp_path):
    campaign, rows = serial_rows
    clustered = run_campaign(campaign, tmp_path / 'out', workers=2, progress=False)
    pd.testing.assert_frame_equal(comparable(clustered), comparable(rows))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def test_a_cluster_of_a_dask_scheduler_and_two_dask_workers_gives_the_serial_rows(
        serial_rows, tmp_path):
    campaign, rows = serial_rows
    port = _free_port()
    address = f'tcp://127.0.0.1:{port}'
    dask = [sys.executable, '-m', 'dask']
    processes = [subprocess.Popen([*dask, 'scheduler', '--host', '127.0.0.1', '--port',
                                   str(port), '--no-dashboard'], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, cwd=tmp_path)]
    try:
        for _ in range(2):
            processes.append(subprocess.Popen(
                [*dask, 'worker', address, '--nthreads', '1', '--no-dashboard'],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path))
        from distributed import Client
        deadline = time.monotonic() + 120
        while True:
            try:
                client = Client(address, timeout='5s')
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        try:
            client.wait_for_workers(2, timeout=120)
            assert len(client.scheduler_info(n_workers=-1)['workers']) == 2
        finally:
            client.close()
        clustered = run_campaign(campaign, tmp_path / 'out', scheduler=address, progress=False)
    finally:
        for process in reversed(processes):
            process.terminate()
        for process in processes:
            try:
                process.wait(30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
    pd.testing.assert_frame_equal(comparable(clustered), comparable(rows))


class Counting:
    """A runner that counts its runs and can interrupt the campaign after ``stop_after``."""

    def __init__(self, stop_after: int | None = None):
        self.ran, self.stop_after = [], stop_after

    def __call__(self, task):
        if self.stop_after is not None and len(self.ran) == self.stop_after:
            raise KeyboardInterrupt
        self.ran.append((task['law'], task['draw']))
        from ato_campaigns.engine import offline_metrics
        return offline_metrics(task)


def test_an_interrupted_campaign_keeps_its_rows_and_resumes_only_the_missing(
        serial_rows, tmp_path):
    campaign, rows = serial_rows
    out = tmp_path / 'out'
    first = Counting(stop_after=3)
    with pytest.raises(KeyboardInterrupt):
        run_campaign(campaign, out, serial=True, runner=first, progress=False)
    kept = read_rows(rows_folder(out, campaign.name), campaign.fingerprint)
    assert len(kept) == 3
    second = Counting()
    resumed = run_campaign(campaign, out, serial=True, runner=second, progress=False)
    assert len(second.ran) == 5 and not set(second.ran) & set(first.ran)
    pd.testing.assert_frame_equal(comparable(resumed), comparable(rows))
    third = Counting()
    run_campaign(campaign, out, serial=True, runner=third, progress=False)
    assert third.ran == []  # complete: nothing runs again


@pytest.mark.parametrize('change, differs', [
    ({'seed': 12}, 'seed (11 there, 12 here)'),
    # shrinking draws used to report 2 draws over the statistics of the 4 stored
    ({'draws': 2}, 'draws (4 there, 2 here)'),
])
def test_a_changed_campaign_is_refused_in_the_folder_of_the_old_one(serial_rows, tmp_path,
                                                                     capsys, change, differs):
    campaign, rows = serial_rows
    out = tmp_path / 'out'
    run_campaign(campaign, out, serial=True, progress=False)
    path = write(tmp_path, {**TINY, **change}, 'changed.yaml')
    changed = load_campaign(path)
    assert changed.fingerprint != campaign.fingerprint
    counting = Counting()
    with pytest.raises(FolderConflict, match=r'holds the rows of another version of this '
                                             r'campaign \(fingerprint ') as refused:
        run_campaign(changed, out, serial=True, runner=counting, progress=False)
    assert differs in str(refused.value) and counting.ran == []
    assert main([str(path), '--serial', '--out', str(out)]) == 2
    assert 'give this campaign another name' in capsys.readouterr().err
    folder = rows_folder(out, campaign.name)
    pd.testing.assert_frame_equal(comparable(read_rows(folder)), comparable(rows))
    renamed = load_campaign(write(tmp_path, {**TINY, **change, 'name': 'tiny_changed'}))
    assert len(run_campaign(renamed, out, serial=True, progress=False)) == 2 * renamed.draws


def test_every_parquet_file_says_what_its_rows_stand_on(tmp_path):
    campaign = load_campaign(write(tmp_path, {**TINY, 'draws': 2, 'end_time_s': 20}))
    out = tmp_path / 'out'
    with pytest.raises(KeyboardInterrupt):   # two part files, then the merged one
        run_campaign(campaign, out, serial=True, runner=Counting(stop_after=2),
                     progress=False)
    folder = rows_folder(out, campaign.name)
    parts = [dataset.file_description(p) for p in sorted(folder.glob('part-*.parquet'))]
    run_campaign(campaign, out, serial=True, progress=False)
    merged = sorted(folder.glob('*.parquet'))
    assert len(parts) == 2 and len(merged) == 1 and merged[0].name.startswith('rows-')
    for description in [*parts, dataset.file_description(merged[0])]:
        assert description['fingerprint'] == campaign.fingerprint
        assert description['identity'] == campaign.identity()
        assert (description['seed'], description['draws']) == (11, 2)
        spec = description['uncertainty']['short_line']
        assert spec['mass_factor'] == uncertainty.DEFAULTS['mass_factor'].describe()
        assert description['run_end']['rule'] == 'window'
        assert description['run_end']['end_time_s'] == 20.0
        assert description['tuning_artefact'] == []   # no tuned configuration
        assert description['configurations'] == ['published'] and description['envelope']
        assert description['commit'] and 'not a git checkout' not in description['commit']


def test_one_row_is_made_again_offline_printed_and_its_arrays_saved(tmp_path, capsys):
    path = write(tmp_path, {**TINY, 'draws': 2, 'end_time_s': 20})
    out = tmp_path / 'out'
    rows = run_campaign(load_campaign(path), out, serial=True, progress=False)
    capsys.readouterr()
    saved = tmp_path / 'run.npz'
    assert main(['--campaign', str(path), '--draw', '1', '--law', 'luo_xu', '--out', str(out),
                 '--save', str(saved)]) == 0
    printed, said = capsys.readouterr()
    shown = json.loads(printed)
    stored = rows[(rows['law'] == LUO) & (rows['draw'] == 1)].iloc[0]
    assert (shown['law'], shown['draw'], shown['status']) == (LUO, 1, stored['status'])
    assert shown['configuration'] == 'published'
    assert shown['rms_speed_error_kmh'] == stored['rms_speed_error_kmh']
    assert shown['drawn']['mass_factor'] == stored['p_mass_factor']
    assert 'the same status and metrics as the stored row' in said
    arrays = np.load(saved)
    assert arrays['times_s'].size == 201 and arrays['times_s'][-1] == pytest.approx(20.0)
    assert arrays['speeds_mps'].shape == arrays['times_s'].shape
    assert any(name.startswith('estimate_') for name in arrays.files)
    for bad, words in ((['--draw', '2', '--law', 'pid'], '--draw: the campaign has draws 0 '
                                                        'to 1, not 2'),
                       (['--draw', '0', '--law', 'pdi'], "--law: 'pdi' is not a law")):
        assert main(['--campaign', str(path), '--out', str(out), *bad]) == 2
        assert words in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['--campaign', str(path), '--draw', '0'])
    assert '--draw and --law go together' in capsys.readouterr().err


def test_the_plant_s_watchdog_brakes_of_a_graph_run_are_in_its_status(tmp_path):
    """A run through the graph hands run_metrics the plant's watchdog brakes (an offline run
    has none): the status names them, as it names the ATP's interventions."""
    from ato_common.run_events import WATCHDOG, RunEvent, RunEvents
    campaign = load_campaign(write(tmp_path, {**TINY, 'draws': 1, 'end_time_s': 20}))
    row, run = engine.rerun(campaign, 'pid', 0)
    assert row['status'] != 'watchdog brake'
    brakes = RunEvents((RunEvent(WATCHDOG, 12.5, 'command watchdog: service brake'),),
                       {WATCHDOG: 1})
    dt = 1.0 / campaign.rates_hz[('short_line', PID)]
    judged = engine.run_metrics(run, dt, brakes)
    assert judged['status'] == 'watchdog brake'
    assert '1 watchdog brakes (first at 12.5 s)' in judged['reason']
    assert {k: v for k, v in judged.items() if k not in ('status', 'reason', 'events')} == {
        k: v for k, v in engine.run_metrics(run, dt).items()
        if k not in ('status', 'reason', 'events')}


def hang_or_fail(task):
    if task['draw'] == 1 and task['law'] == PID:
        while True:  # a law that never returns
            pass
    if task['draw'] == 2:
        raise ZeroDivisionError('estimate reached zero')
    from ato_campaigns.engine import offline_metrics
    return offline_metrics(task)


@pytest.mark.parametrize('engine', ['serial', 'dask'])
def test_a_hanging_run_times_out_a_failing_one_is_reported_and_the_campaign_completes(
        tmp_path, engine):
    campaign = load_campaign(write(tmp_path, {**TINY, 'timeout_s': 3}))
    client = None
    if engine == 'dask':
        from distributed import Client, LocalCluster
        client = Client(LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                     dashboard_address=':0'))
    try:
        rows = run_campaign(campaign, tmp_path / 'out', serial=engine == 'serial',
                            client=client, runner=hang_or_fail, progress=False)
    finally:
        if client is not None:
            client.close()
    assert len(rows) == 8
    status = {(r.law, r.draw): (r.status, r.reason) for r in rows.itertuples()}
    assert status[(PID, 1)][0] == 'timeout' and '3 s' in status[(PID, 1)][1]
    for law in (PID, LUO):
        assert status[(law, 2)][0] == 'error'
        assert 'ZeroDivisionError: estimate reached zero' in status[(law, 2)][1]
    assert [status[(law, d)][0] for law in (PID, LUO) for d in (0, 3)] == ['ok'] * 4
    failed = rows[rows['status'] != 'ok']
    assert failed['rms_speed_error_kmh'].isna().all()
    assert (failed['p_mass_factor'] > 0).all()  # the drawn parameters are kept


def test_a_runner_s_status_is_kept_and_a_missing_one_is_an_error(tmp_path):
    campaign = load_campaign(write(tmp_path, TINY))
    task = campaign.tasks()[0]
    row = run_task(task, runner=lambda t: {'max_speed_error_kmh': 80.0, 'status': 'late',
                                           'reason': 'late: B 12.0 s after the timetable'})
    assert row['status'] == 'late' and row['max_speed_error_kmh'] == 80.0
    row = run_task(task, runner=lambda t: {'max_speed_error_kmh': 80.0})
    assert row['status'] == 'error' and 'the run gave no valid status' in row['reason']


#: a 20 km line driven to a timetable with 1 % of running time supplement; its traction drive
#: fails as each scenario says
LOSS_LINE = """
name: {name}
train: {{preset: crh3_luo_xu}}
line: {{name: loss, length_m: 20000, stations: [{{name: A, position_m: 0}},
       {{name: B, position_m: 20000}}], speed_limits: [{{start_m: 0, speed_kmh: 300}}]}}
planning: {{max_acceleration_mps2: 0.4, service_deceleration_mps2: 0.5, max_jerk_mps3: 0.3,
           speed_margin_kmh: 5}}
timetable: {{strategy: timetable, supplement_percent: 1.0}}
plant: {{failures: [{failure}]}}
"""


def test_a_late_train_is_late_and_a_stranded_one_did_not_finish(tmp_path):
    """Defect 7: a train that arrives late after a traction loss (replanned, it cannot make up
    60 s of lost traction with 1 % of supplement) is late, not unfinished; one whose traction
    is lost for good stands short of B until the run's limit past the timetable: did not
    finish. Each is counted under its own kind."""
    (tmp_path / 'late.yaml').write_text(LOSS_LINE.format(
        name='late', failure='{actuator: traction, kind: loss, start_s: 100, end_s: 160}'))
    (tmp_path / 'stranded.yaml').write_text(LOSS_LINE.format(
        name='stranded', failure='{actuator: traction, kind: loss, start_s: 60}'))
    campaign = load_campaign(write(tmp_path, dict(
        TINY, draws=1, laws=['pid'], scenarios=['late.yaml', 'stranded.yaml'],
        uncertainty='nominal', end_time_s=0, timeout_s=300)))
    rows = run_campaign(campaign, tmp_path / 'out', serial=True, progress=False)
    by = {Path(r.scenario).stem: r for r in rows.itertuples()}
    late, stranded = by['late'], by['stranded']
    assert late.status == 'late' and late.reason.startswith('late: B ')
    assert late.arrival_delay_s >= LATE_AFTER_S and late.stop_error_m < 0.5
    assert stranded.status == 'did not finish'
    assert stranded.reason.startswith('did not finish: the train never stood within its '
                                      'length (200 m) of B')
    rates = cs.failure_rates(rows).set_index(['scenario', 'kind'])
    counts = {(Path(s).stem, kind): k for (s, kind), k in rates['k'].items()}
    assert counts[('late', 'late')] == 1 and counts[('late', 'did not finish')] == 0
    assert counts[('stranded', 'did not finish')] == 1 and counts[('stranded', 'late')] == 0
    assert counts[('late', 'not ok')] == counts[('stranded', 'not ok')] == 1


def test_a_train_stopped_short_by_its_odometer_bias_finishes_its_journey():
    # The cause of pid's "did not finish" under the default uncertainty: an odometer reading
    # 0.75 m ahead makes the ATO stop 0.75 m short of Midway; the plant's ATP took the true
    # position, never saw the train at the stop and held it there for ever. The stop check
    # now takes the odometer's reading, as the on-board unit reports it. (A position bias is
    # a start-of-mission error the first balise group corrects: on a line declared without
    # balise groups, with an odometry declared exact, it stays for the run.)
    values = {name: p.nominal for name, p in uncertainty.PARAMETERS.items()}
    values['position_bias_m'] = 0.75
    data = yaml.safe_load(resources.files('ato_common').joinpath(
        'scenarios/short_line.yaml').read_text())
    data['line']['balise_groups'] = []
    del data['supervision']
    run = run_offline(parse_scenario(data), 'pid', uncertainty=values)
    assert unfinished(run) == ''
    assert run.metrics().stop_errors_m['Midway'] == pytest.approx(-0.75, abs=0.05)
    assert run.positions[-1] == pytest.approx(36000.0 - 0.75, abs=0.05)
    # the law stopped where its odometer put the stop: the part of the stop error it can act
    # on is small, the row says both
    odometer = run.odometer_stop_errors_m()
    assert odometer.keys() == run.metrics().stop_errors_m.keys()
    assert odometer['Midway'] == pytest.approx(0.0, abs=0.05)
    row = engine.run_metrics(run, 0.1)
    assert row['stop_error_m'] == pytest.approx(0.75, abs=0.05)
    assert row['odometer_stop_error_m'] == pytest.approx(0.0, abs=0.05)
    # a run without the odometer's readings has no odometer stop error (NaN), not a crash
    unread = dataclasses.replace(run, measured_positions=np.zeros(0))
    assert unread.odometer_stop_errors_m() == {}
    assert math.isnan(engine.run_metrics(unread, 0.1)['odometer_stop_error_m'])
    # a train held short of its stop (the old behaviour) is named as unfinished
    stranded = dataclasses.replace(run, positions=np.minimum(run.positions, 14000.0 - 300.0))
    assert 'never stood within its length (200 m) of Midway' in unfinished(stranded)


def test_a_campaign_without_uncertainty_draws_from_each_scenarios_section(tmp_path):
    data = yaml.safe_load(Path(str(resources.files('ato_common') / 'scenarios'
                                   / 'short_line.yaml')).read_text())
    data['uncertainty'] = {'defaults': False, 'wind_mps': 7.0}
    write(tmp_path, data, 'windy.yaml')
    campaign = load_campaign(write(tmp_path, dict(TINY, scenarios=['short_line',
                                                                   'windy.yaml'])))
    windy = str((tmp_path / 'windy.yaml').resolve())
    assert campaign.spec is None
    assert campaign.specs['short_line'] == uncertainty.DEFAULTS
    assert [t['values']['wind_mps'] for t in campaign.tasks() if t['scenario'] == windy] == \
        [7.0] * 8
    assert {t['values']['mass_factor'] for t in campaign.tasks() if t['scenario'] == windy} \
        == {1.0}
    given = load_campaign(write(tmp_path, dict(TINY, scenarios=['windy.yaml'],
                                               uncertainty='nominal')))
    assert given.specs[windy] == uncertainty.NOMINAL


# --- statistics against values computed by hand ---------------------------------------------

def fixed_table() -> pd.DataFrame:
    """2 laws x 5 draws; law B is A + (1, 2, 3, 4, 5), and B's draw 4 timed out."""
    a = [1.0, 2.0, 3.0, 4.0, 10.0]
    b = [2.0, 4.0, 6.0, 8.0, math.nan]
    rows = []
    for law, values in (('A', a), ('B', b)):
        for draw, v in enumerate(values):
            rows.append({'scenario': 's', 'law': law, 'draw': draw,
                         'status': 'ok' if math.isfinite(v) else 'timeout',
                         'rms_speed_error_kmh': v,
                         'stop_error_m': [0.1, -0.6, 0.2, 0.7, 0.3][draw],
                         'atp_interventions': [0, 0, 1, 0, 0][draw] if law == 'A' else 0,
                         'p_mass_factor': [1.0, 1.1, 1.2, 1.3, 1.4][draw],
                         'p_wind_mps': [0.0, -1.0, 3.0, 1.0, 2.0][draw]})
    return pd.DataFrame(rows)


def test_summary_statistics_match_hand_computed_values():
    table = cs.summary(fixed_table(), 'rms_speed_error_kmh').set_index('law')
    # A: 1, 2, 3, 4, 10 -> mean 4, median 3, p95 (linear) 4 + 0.8 (10 - 4) = 8.8, worst 10
    assert table.loc['A', ['n_ok', 'mean', 'median', 'p95', 'worst']].tolist() == \
        pytest.approx([5, 4.0, 3.0, 8.8, 10.0])
    # B over its 4 ok runs: 2, 4, 6, 8 -> mean 5, median 5, p95 6 + 0.85 * 2 = 7.7, worst 8
    assert table.loc['B', ['n_ok', 'mean', 'median', 'p95', 'worst']].tolist() == \
        pytest.approx([4, 5.0, 5.0, 7.7, 8.0])


def test_failure_rates_and_their_wilson_intervals_match_hand_computed_values():
    rates = cs.failure_rates(fixed_table()).set_index(['law', 'kind'])
    stop = 'stop outside +/-0.5 m'
    assert rates.loc[('A', stop), ['k', 'n']].tolist() == [2, 5]   # -0.6 and 0.7
    assert rates.loc[('B', stop), ['k', 'n']].tolist() == [3, 5]   # and the timed out run
    assert rates.loc[('A', 'ATP intervention'), 'k'] == 1
    assert rates.loc[('B', 'did not finish'), 'k'] == 1
    # Wilson score interval, k = 2 of n = 5, z = 1.959964:
    z, n, p = 1.959963984540054, 5, 0.4
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    assert rates.loc[('A', stop), ['low', 'high']].tolist() == pytest.approx(
        [centre - half, centre + half])


def test_paired_differences_use_the_same_draws_and_a_bootstrap_interval():
    table = cs.paired_differences(fixed_table(), 'A', 'rms_speed_error_kmh')
    r = table.iloc[0]
    # pairs on draws 0-3 only (B's draw 4 timed out): differences 1, 2, 3, 4
    assert r['law'] == 'B' and r['pairs'] == 4 and r['mean_diff'] == pytest.approx(2.5)
    # the mean of a resample of {1, 2, 3, 4} lies in [1, 4]; the interval is around 2.5
    assert 1.0 <= r['low'] < 2.5 < r['high'] <= 4.0


def test_the_ranking_says_when_two_laws_cannot_be_told_apart():
    rows = fixed_table()
    # 4 pairs, B - A = 1, 2, 3, 4: the bootstrap interval excludes 0, but 4 pairs are too few
    # to tell two laws apart (they used to be told apart)
    assert cs.fewest_pairs(rows, 's') == 4 < cs.MIN_PAIRS
    assert cs.ranking(rows, 's', 'rms_speed_error_kmh') == [('A', 4.0, True), ('B', 5.0, False)]
    many = paired_table(cs.MIN_PAIRS, lambda a, draw: a + 1.0 + 0.1 * (draw % 3))
    assert cs.ranking(many, 's', 'rms_speed_error_kmh')[1][2] is True
    noisy = paired_table(cs.MIN_PAIRS, lambda a, draw: a + (3.0 if draw % 2 else -2.9))
    ranked = cs.ranking(noisy, 's', 'rms_speed_error_kmh')
    assert [law for law, _, _ in ranked] == ['A', 'B'] and ranked[1][2] is False


def paired_table(draws: int, b_of: Callable[[float, int], float]) -> pd.DataFrame:
    """Laws A and B on ``draws`` draws, every run ok: A's RMS speed error 1 + draw / 10, B's
    ``b_of(A's, draw)``."""
    rows = []
    for draw in range(draws):
        a = 1.0 + draw / 10
        for law, value in (('A', a), ('B', b_of(a, draw))):
            rows.append({'scenario': 's', 'law': law, 'draw': draw, 'status': 'ok',
                         'rms_speed_error_kmh': value, 'stop_error_m': 0.1,
                         'atp_interventions': 0.0})
    return pd.DataFrame(rows)


def test_a_report_of_too_few_pairs_warns(tmp_path, serial_rows):
    from ato_campaigns import report as campaign_report
    campaign, rows = serial_rows
    text = campaign_report.markdown(campaign, rows, 'cmd', 1.0, plots=False)
    assert f'**Warning: only 4 paired draws** (fewer than {cs.MIN_PAIRS})' in text
    assert 'every other law is told apart' not in text


def test_the_report_names_how_its_rows_were_run_from_the_rows(serial_rows):
    """A campaign's own rows are the offline loop's; rows made another way (through the ROS
    graph, an external node) say so in their ``through`` column, and the report names that."""
    from ato_campaigns import report as campaign_report
    campaign, rows = serial_rows
    text = campaign_report.markdown(campaign, rows, 'cmd', 1.0, plots=False)
    assert f'; {campaign_report.OFFLINE}, the plant perturbed' in text
    through = rows.assign(through='through the ROS graph (the nodes in lockstep)')
    text = campaign_report.markdown(campaign, through, 'cmd', 1.0, plots=False)
    assert '; through the ROS graph (the nodes in lockstep), the plant perturbed' in text
    assert campaign_report.OFFLINE not in text
    mixed = through.assign(through=through['through'].where(through['law'] != PID))
    text = campaign_report.markdown(campaign, mixed, 'cmd', 1.0, plots=False)
    assert (f'; {campaign_report.OFFLINE} ({PID}); through the ROS graph (the nodes in lockstep) '
            f'({LUO}), the plant perturbed') in text


def test_sensitivity_ranks_the_parameter_that_drives_the_error_first():
    table = cs.sensitivity(fixed_table(), 'rms_speed_error_kmh')
    first = table[table['law'] == 'A'].iloc[0]
    assert first['parameter'] == 'mass_factor' and first['rho'] == pytest.approx(1.0)
    wind = table[(table['law'] == 'A') & (table['parameter'] == 'wind_mps')].iloc[0]
    # ranks of wind 0, -1, 3, 1, 2 -> 2, 1, 5, 3, 4 against 1..5: rho = 1 - 6*8/(5*24) = 0.6
    assert wind['rho'] == pytest.approx(0.6)


def test_the_command_writes_the_report_and_its_plots(tmp_path):
    path = write(tmp_path, {**TINY, 'draws': 2, 'end_time_s': 20})
    page = tmp_path / 'page.md'
    assert main([str(path), '--serial', '--out', str(tmp_path / 'out'),
                 '--results-page', str(page)]) == 0
    folder = tmp_path / 'out' / 'tiny'
    report = (folder / 'report.md').read_text()
    assert '## short_line' in report and 'Ranking by mean RMS speed error' in report
    assert '`mass_factor`' in report and 'EN 15663' in report
    for kind in ('metrics', 'stop_ecdf', 'sensitivity', 'pareto', 'convergence'):
        assert (folder / f'short_line_{kind}.png').stat().st_size > 1000
    assert page.read_text().startswith('# Campaign tiny')
    # every statistic also as CSV and JSON, with the methods stated
    for name in ('overview', 'metrics', 'failure_rates', 'paired_failures',
                 'paired_differences', 'signed_stop_errors', 'pareto', 'convergence',
                 'sensitivity', 'ranking'):
        assert (folder / 'stats' / f'{name}.csv').is_file(), name
    saved = json.loads((folder / 'report.json').read_text())
    assert saved['methods']['bootstrap_resamples'] == cs.BOOTSTRAP_RESAMPLES
    assert saved['methods']['bootstrap_method'] == cs.BOOTSTRAP_METHOD
    diffs = pd.read_csv(folder / 'stats' / 'paired_differences.csv')
    assert len(saved['tables']['paired_differences']) == len(diffs) > 0
    assert f'{cs.BOOTSTRAP_RESAMPLES} resamples' in report and 'McNemar' in report
    assert 'Signed stop errors' in report and 'Pareto view' in report
    assert os.listdir(folder / 'rows') and len(list((folder / 'rows').glob('*.parquet'))) == 1


def test_the_controller_of_a_perturbed_run_knows_the_nominal_train_only(monkeypatch):
    from ato_common import uncertainty as u
    from ato_common.knowledge import knowledge_of
    from ato_common.scenario import load_scenario
    from ato_simulation import loop as offline
    seen = {}
    real_host, real_sim = offline.ControllerHost, offline.TrainSimulation

    def host(knowledge, *args, **kwargs):
        seen['knowledge'] = knowledge
        return real_host(knowledge, *args, **kwargs)

    def sim(scenario, *args, **kwargs):
        seen['truth'] = scenario
        return real_sim(scenario, *args, **kwargs)

    monkeypatch.setattr(offline, 'ControllerHost', host)
    monkeypatch.setattr(offline, 'TrainSimulation', sim)
    scenario = load_scenario('short_line')
    values = u.draw(u.parse_uncertainty({'mass_factor': 1.15}), 1, 0)
    offline.run_offline(scenario, 'pid', end_time_s=2.0, uncertainty=values)
    assert seen['knowledge'] == knowledge_of(scenario)
    assert seen['truth'].train.mass_kg > scenario.train.mass_kg * 1.1


def test_a_diverged_run_counts_in_the_distribution_and_a_failed_one_does_not():
    rows = fixed_table()
    rows.loc[(rows['law'] == 'A') & (rows['draw'] == 4), 'status'] = 'diverged'
    rows.loc[(rows['law'] == 'A') & (rows['draw'] == 0), 'status'] = 'error'
    table = cs.summary(rows, 'rms_speed_error_kmh').set_index('law')
    assert table.loc['A', ['n_ok', 'mean', 'worst']].tolist() == pytest.approx([4, 4.75, 10.0])


def test_the_readme_summary_is_written_between_its_markers_only(tmp_path, serial_rows):
    from ato_campaigns import report as campaign_report
    campaign, rows = serial_rows
    readme = tmp_path / 'README.md'
    readme.write_text(f'# x\n\nbefore\n{campaign_report.README_START}\nOLD SUMMARY\n'
                      f'{campaign_report.README_END}\nafter\n')
    campaign_report.update_readme(readme, campaign_report.summary_markdown(campaign, rows, 'cmd'))
    text = readme.read_text()
    assert text.startswith('# x\n\nbefore\n') and text.endswith('after\n')
    assert 'OLD SUMMARY' not in text
    assert f'| {PID} |' in text and f'| {LUO} |' in text and '**short_line**' in text
    readme.write_text('no markers')
    with pytest.raises(ValueError, match='no campaign summary markers'):
        campaign_report.update_readme(readme, 'x')


def test_a_hidden_gradient_changes_the_controller_only_and_the_closed_loop_shows_it():
    from train_plant_node.simulation import TrainSimulation
    scenario = load_scenario('short_line')
    values = {name: p.nominal for name, p in uncertainty.PARAMETERS.items()}
    hidden = dict(values, gradient_known=0.0)
    # the plant's truth, and its grade force, are the nominal ones
    assert uncertainty.perturbed(scenario, hidden) is scenario
    sims = [TrainSimulation(uncertainty.perturbed(scenario, v)) for v in (hidden, values)]
    for sim in sims:
        sim.state[:2] = (20000.0, 30.0)  # on the 12 per mille grade, coasting at 30 m/s
    hidden_accel, nominal_accel = (sim.truth().accelerations[0] for sim in sims)
    assert hidden_accel == nominal_accel < -9.80665 * 0.012   # the grade decelerates it
    # the closed loop: the PID feeds no grade forward, and tracks the grades worse
    known_run = run_offline(scenario, 'pid', end_time_s=400.0, uncertainty=values)
    hidden_run = run_offline(scenario, 'pid', end_time_s=400.0, uncertainty=hidden)
    assert np.array_equal(known_run.ref_speeds, hidden_run.ref_speeds)
    assert not np.array_equal(known_run.forces, hidden_run.forces)
    assert hidden_run.metrics().rms_speed_error_kmh > known_run.metrics().rms_speed_error_kmh


def test_a_law_entry_can_hide_the_gradient_on_the_same_draws(tmp_path):
    example = resources.files('ato_campaigns') / 'campaigns' / 'hidden_gradient.yaml'
    assert [(e.label, e.gradient) for e in load_campaign(Path(str(example))).laws] == [
        (PID, 'drawn'), ('pid_gradient_hidden/published', 'hidden')]
    data = dict(TINY, draws=2, end_time_s=300,
                laws=['pid', {'law': 'pid', 'label': 'flat', 'gradient': 'hidden'}])
    rows = run_campaign(load_campaign(write(tmp_path, data)), tmp_path / 'out', serial=True,
                        progress=False)
    pid, flat = (rows[rows['law'] == law].reset_index(drop=True)
                 for law in (PID, 'flat/published'))
    assert list(pid['p_gradient_known']) == [1.0, 1.0]
    assert list(flat['p_gradient_known']) == [0.0, 0.0]
    plant = [c for c in rows.columns if c.startswith('p_') and c != 'p_gradient_known']
    assert pid[plant].equals(flat[plant])   # the same plants: the difference is paired
    assert (pid['rms_speed_error_kmh'] != flat['rms_speed_error_kmh']).all()
    with pytest.raises(ConfigError, match=r"laws\[0\].gradient: 'flat' is not valid; valid: "
                                          'drawn, known, hidden'):
        load_campaign(write(tmp_path, dict(TINY, laws=[{'law': 'pid', 'gradient': 'flat'}]),
                            'bad.yaml'))


def test_a_worker_parses_a_scenario_once_per_file_version(tmp_path):
    from ato_campaigns.engine import task_scenario
    assert task_scenario('short_line') is task_scenario('short_line')
    source = resources.files('ato_common') / 'scenarios' / 'short_line.yaml'
    path = tmp_path / 'mine.yaml'
    path.write_text(source.read_text())
    first = task_scenario(str(path))
    assert task_scenario(str(path)) is first and first.name == 'short_line'
    data = yaml.safe_load(path.read_text())
    data['name'] = 'edited'
    path.write_text(yaml.safe_dump(data))
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    assert task_scenario(str(path)).name == 'edited'   # an edited file is parsed again


def _worker_settings():
    import dask
    return {key: dask.config.get(key) for key in engine.WORKER_SETTINGS}


def _run_process_view():
    """On a worker: the process id and the frozen objects of its run process (asked through
    the run process itself)."""
    import gc
    import os

    from ato_campaigns.run_process import worker_run_process
    return worker_run_process().call(lambda: (os.getpid(), gc.get_freeze_count()), None), \
        os.getpid()


def test_the_local_cluster_s_workers_run_without_the_profiler_and_their_runs_in_a_process():
    client, cluster = engine.open_client(workers=1)
    try:
        (settings,) = client.run(_worker_settings).values()
        assert settings == engine.WORKER_SETTINGS
        assert settings['distributed.worker.profile.enabled'] is False
        task = dict(engine.parse_campaign(TINY, 'tiny', Path.cwd()).tasks()[0], end_time_s=5.0)
        assert client.submit(run_task, task, pure=False).result()['status'] == 'ok'
        (run_pid, frozen), worker_pid = client.submit(_run_process_view, pure=False).result()
        assert run_pid != worker_pid   # the run ran in a process of its own
        assert frozen > 0   # whose heap after its first run is out of the collector's sight
    finally:
        client.close()
        cluster.close()
