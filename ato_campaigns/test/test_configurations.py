"""The configurations of a campaign (ato_campaigns.engine): every law published and tuned on the
same draws, as rows of their own; a law without a tuned artefact refused before anything runs;
configurations, tuned gains and the envelope in the fingerprint and the rows' metadata; the
baseline; the loop margins beside the results in the report and the README's summary; one row
again in a configuration."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pandas as pd
import pytest
import yaml

from ato_campaigns import dataset
from ato_campaigns import report as campaign_report
from ato_campaigns.campaign import main
from ato_campaigns.engine import load_campaign, rows_folder, run_campaign
from ato_campaigns.margins import campaign_margins
from ato_common.validation import ConfigError
from ato_controller_node import gains

#: two laws in both configurations on 3 draws of the short line's first 10 s
BOTH = {'name': 'both', 'seed': 11, 'draws': 3, 'scenarios': ['short_line'],
        'laws': ['pid', 'luo_xu'], 'end_time_s': 10, 'timeout_s': 120}
TRAIN = 'crh3_luo_xu'


def write(tmp_path: Path, data: dict, name: str = 'campaign.yaml') -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def stand_in(task) -> dict:
    """A run's row without the run: an RMS speed error from the settings and the draw, so
    that the configurations differ and the draws pair."""
    kp = task['settings'].get('kp_position', task['settings'].get('c1', 0.5))
    rms = 1.0 + kp + 0.1 * task['draw']
    return {'status': 'ok', 'reason': '', 'rms_speed_error_kmh': rms,
            'stop_error_m': 0.1, 'traction_energy_kwh': 1000.0 + rms,
            'atp_interventions': 0.0}


def test_every_law_runs_in_each_configuration_on_the_same_draws(tmp_path):
    campaign = load_campaign(write(tmp_path, BOTH))
    assert campaign.configurations == ('published', 'tuned')
    assert [e.label for e in campaign.laws] == ['pid/published', 'pid/tuned',
                                                'luo_xu/published', 'luo_xu/tuned']
    tasks = campaign.tasks()
    assert len(tasks) == 3 * 4
    for draw in range(3):
        values = [t['values'] for t in tasks if t['draw'] == draw]
        assert len(values) == 4 and all(v == values[0] for v in values)
    by_label = {t['law']: t for t in tasks if t['draw'] == 0}
    for law in ('pid', 'luo_xu'):
        assert by_label[f'{law}/published']['settings'] == {}   # the law's defaults
        assert by_label[f'{law}/tuned']['settings'] == dict(gains.tuned_artefact(
            law, TRAIN).settings)
        assert (by_label[f'{law}/tuned']['configuration'], by_label[f'{law}/tuned']['law_name']) \
            == ('tuned', law)
    rows = run_campaign(campaign, tmp_path / 'out', serial=True, runner=stand_in,
                        progress=False)
    assert len(rows) == 12 and set(rows['configuration']) == {'published', 'tuned'}
    assert set(rows['law_name']) == {'pid', 'luo_xu'}
    pid = rows[rows['law_name'] == 'pid'].pivot(index='draw', columns='configuration',
                                                 values='rms_speed_error_kmh')
    assert (pid['tuned'] != pid['published']).all()   # paired on each draw, different gains
    tuned_row = rows[rows['law'] == 'pid/tuned'].iloc[0]
    assert json.loads(tuned_row['settings']) == dict(gains.tuned_artefact('pid', TRAIN).settings)


def test_a_law_entry_with_settings_runs_them_on_top_of_each_configuration(tmp_path):
    data = dict(BOTH, laws=[{'law': 'pid', 'settings': {'kd_speed': 2.0}, 'label': 'pid_d'}])
    tasks = {t['law']: t for t in load_campaign(write(tmp_path, data)).tasks()
             if t['draw'] == 0}
    assert tasks['pid_d/published']['settings'] == {'kd_speed': 2.0}
    tuned = dict(gains.tuned_artefact('pid', TRAIN).settings, kd_speed=2.0)
    assert tasks['pid_d/tuned']['settings'] == tuned


@pytest.fixture
def only_pid_tuned(tmp_path, monkeypatch):
    """A folder of tuned artefacts that holds the PID's only."""
    folder = tmp_path / 'tuned'
    (folder / TRAIN).mkdir(parents=True)
    shutil.copy(gains.artefact_path('pid', TRAIN), folder / TRAIN / 'pid.json')
    monkeypatch.setattr(gains, 'TUNED_DIR', folder)
    return folder


def test_a_law_without_a_tuned_artefact_is_refused_before_anything_runs(
        tmp_path, capsys, only_pid_tuned):
    path = write(tmp_path, BOTH)
    with pytest.raises(ConfigError) as refused:
        load_campaign(path)
    message = str(refused.value)
    assert str(path) in message and 'laws[1]: luo_xu has no tuned gains for the train ' \
        'crh3_luo_xu' in message and 'configurations: [published]' in message
    assert '(tuned: pid on crh3_luo_xu)' in message
    assert main([str(path), '--serial', '--out', str(tmp_path / 'out')]) == 2
    assert 'luo_xu has no tuned gains' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()   # nothing ran, nothing fell back to published
    published = load_campaign(write(tmp_path, dict(BOTH, configurations=['published']),
                                    'published.yaml'))
    assert [e.label for e in published.laws] == ['pid/published', 'luo_xu/published']


def test_tuned_gains_are_not_evaluated_on_their_training_seed(tmp_path):
    seed = gains.tuned_artefact('pid', TRAIN).record['training']['seed']
    with pytest.raises(ConfigError, match=f'seed: {seed} is the seed the tuned gains of pid '):
        load_campaign(write(tmp_path, dict(BOTH, seed=seed)))
    load_campaign(write(tmp_path, dict(BOTH, seed=seed, configurations=['published']), 'p.yaml'))


@pytest.mark.parametrize('change, field, words', [
    ({'configurations': ['published', 'best']}, 'configurations[1]',
     "'best' is not valid; valid: published, tuned"),
    ({'configurations': []}, 'configurations', 'must be a non-empty list'),
    ({'configurations': ['tuned', 'tuned']}, 'configurations', 'each configuration once'),
    ({'envelope': 'sometimes'}, 'envelope', 'must be on or off'),
    ({'laws': [{'law': 'pid', 'label': 'pid/fast'}]}, 'laws[0].label', "has a '/'"),
    ({'baseline': 'tan_weighted_mm'}, 'baseline', 'pid/published, pid/tuned'),
])
def test_bad_configurations_and_envelopes_are_refused(tmp_path, change, field, words):
    with pytest.raises(ConfigError) as refused:
        load_campaign(write(tmp_path, {**BOTH, **change}))
    assert field in str(refused.value) and words in str(refused.value)


def test_configurations_tuned_gains_and_the_envelope_are_in_the_fingerprint(tmp_path, monkeypatch):
    def fingerprint(name: str, **change) -> str:
        return load_campaign(write(tmp_path, {**BOTH, **change}, f'{name}.yaml')).fingerprint

    both = fingerprint('both')
    assert fingerprint('again') == both
    assert fingerprint('explicit', configurations=['published', 'tuned'], envelope='on') == both
    assert fingerprint('yaml_on', envelope=True) == both   # `envelope: on` in a YAML file
    others = [fingerprint('published', configurations=['published']),
              fingerprint('tuned', configurations=['tuned']),
              fingerprint('off', envelope='off')]
    assert len({both, *others}) == 4
    # another tuning (other gains in the artefact) is another campaign
    folder = tmp_path / 'retuned'
    shutil.copytree(gains.TUNED_DIR, folder)
    path = folder / TRAIN / 'pid.json'
    record = json.loads(path.read_text())
    record['settings']['kp_position'] *= 1.1
    path.write_text(json.dumps(record))
    monkeypatch.setattr(gains, 'TUNED_DIR', folder)
    assert fingerprint('retuned') != both
    assert fingerprint('retuned_published', configurations=['published']) == others[0]


def test_the_envelope_setting_reaches_every_run(tmp_path, monkeypatch):
    from ato_simulation import loop
    seen = []
    real = loop.run_offline

    def spy(*args, **kwargs):
        seen.append((kwargs['envelope'], kwargs['gains']))
        return real(*args, **dict(kwargs, end_time_s=2.0))

    monkeypatch.setattr(loop, 'run_offline', spy)
    campaign = load_campaign(write(tmp_path, dict(BOTH, draws=1, envelope='off')))
    rows = run_campaign(campaign, tmp_path / 'out', serial=True, progress=False)
    assert seen and {envelope for envelope, _ in seen} == {False}
    assert {g for _, g in seen} == {'published'}   # the tuned settings come with the task
    assert set(rows['envelope']) == {False}


def test_the_rows_metadata_names_each_tuned_artefact(tmp_path):
    campaign = load_campaign(write(tmp_path, dict(BOTH, draws=1)))
    run_campaign(campaign, tmp_path / 'out', serial=True, runner=stand_in, progress=False)
    (path,) = rows_folder(tmp_path / 'out', 'both').glob('*.parquet')
    description = dataset.file_description(path)
    assert description['configurations'] == ['published', 'tuned'] and description['envelope']
    assert description['baseline'] == 'pid/tuned'
    used = {(a['law'], a['train']): a for a in description['tuning_artefact']}
    assert set(used) == {('pid', TRAIN), ('luo_xu', TRAIN)}
    for (law, train), artefact in used.items():
        record = gains.tuned_artefact(law, train).record
        assert artefact['procedure'] == record['procedure']
        assert artefact['budget'] == record['budget']
        assert artefact['seed'] == record['training']['seed']
        assert artefact['commit'] == record['produced']['commit']
        assert artefact['settings'] == record['settings']
        assert artefact['file'] == f'ato_controller_node/ato_controller_node/tuned/{train}/' \
                                   f'{law}.json'


@pytest.mark.parametrize('change, baseline', [
    ({}, 'pid/tuned'),                                     # the PID, tuned when tuned runs
    ({'configurations': ['published']}, 'pid/published'),
    ({'baseline': 'luo_xu'}, 'luo_xu/tuned'),              # an entry: its tuned configuration
    ({'baseline': 'luo_xu/published'}, 'luo_xu/published'),  # a row label as it is
    ({'laws': ['luo_xu', 'pid']}, 'pid/tuned'),            # the PID wherever it is listed
    ({'laws': ['luo_xu', 'tan_weighted_mm']}, 'luo_xu/tuned'),  # no PID: the first entry
])
def test_the_baseline(tmp_path, change, baseline):
    assert load_campaign(write(tmp_path, {**BOTH, **change})).baseline == baseline


@pytest.fixture(scope='module')
def reported(tmp_path_factory):
    """A report of both configurations (stand-in runs) with the margins beside it."""
    folder = tmp_path_factory.mktemp('report')
    campaign = load_campaign(write(folder, BOTH))
    rows = run_campaign(campaign, folder / 'out', serial=True, runner=stand_in, progress=False)
    readme = folder / 'README.md'
    readme.write_text(f'x\n{campaign_report.README_START}\n{campaign_report.README_END}\n')
    margins = campaign_margins(campaign)
    campaign_report.write_report(campaign, rows, folder / 'out' / 'both', 'cmd', 1.0,
                                 readme=readme, law_columns=margins)
    return campaign, rows, margins, folder


def test_the_margins_are_those_of_the_settings_each_row_ran(reported):
    from ato_campaigns import margins as m
    from ato_common.scenario import load_scenario
    campaign, _, margins, _ = reported
    scenario = load_scenario('short_line')
    by_label = margins.set_index('law')
    for law in ('pid', 'luo_xu'):
        for configuration in ('published', 'tuned'):
            expected = m.margins(law, configuration, scenario)
            row = by_label.loc[f'{law}/{configuration}']
            assert row['configuration'] == configuration
            assert row['phase_margin_deg'] == pytest.approx(expected.phase_margin_deg)
            assert row['stable_nominal'] == expected.stable
            worst = m.loop_margins(m.law_loop(law, scenario, campaign.settings_of(
                'short_line', next(e for e in campaign.laws if e.label == f'{law}/'
                                   f'{configuration}'))), m.largest_actuator(
                campaign.specs['short_line']))
            assert row['covers_actuator_draws'] == worst.stable


def test_the_report_shows_the_margins_beside_the_results(reported):
    campaign, _, margins, folder = reported
    out = folder / 'out' / 'both'
    text = (out / 'report.md').read_text()
    assert '## Gains, envelope, baseline' in text and '**pid/tuned**' in text
    assert '### Loop margins' in text and 'lag 1 s, dead time 0.5 s' in text
    assert '| pid/tuned | tuned |' in text
    uncovered = margins[~margins['covers_actuator_draws'].astype(bool)]
    assert len(uncovered)   # the published PID cannot cover the default actuator draws
    for label in uncovered['law']:
        assert f'- `{label}`: its loop cannot cover the actuator draws' in text
    assert '| pid | crh3_luo_xu | 31, 8 on short_line |' in text   # the artefacts used
    csv = pd.read_csv(out / 'stats' / 'margins.csv')
    assert {'law', 'configuration', 'phase_margin_deg', 'delay_margin_s', 'stable_nominal',
            'worst_phase_margin_deg', 'covers_actuator_draws'} <= set(csv.columns)
    saved = json.loads((out / 'report.json').read_text())
    assert saved['configurations'] == ['published', 'tuned'] and saved['baseline'] == 'pid/tuned'
    assert len(saved['tables']['margins']) == 4 and len(saved['tuning_artefacts']) == 2
    overview = pd.read_csv(out / 'stats' / 'overview.csv').set_index('law')
    assert overview.loc['pid/tuned', 'configuration'] == 'tuned'
    assert math.isfinite(overview.loc['pid/tuned', 'phase_margin_deg'])
    tuning = pd.read_csv(out / 'stats' / 'tuned_vs_published.csv')
    rms = tuning[(tuning['entry'] == 'pid') & (tuning['metric'] == 'rms_speed_error_kmh')]
    assert (rms['law'].item(), rms['baseline'].item(), rms['pairs'].item()) == (
        'pid/tuned', 'pid/published', 3)
    assert '### Tuned against published' in text and '| pid | 3 | ' in text
    paired = pd.read_csv(out / 'stats' / 'paired_differences.csv')
    assert set(paired['baseline']) == {'pid/tuned'} and 'pid/tuned' not in set(paired['law'])


def test_the_readme_summary_shows_both_configurations_with_their_margins(reported):
    campaign, rows, margins, folder = reported
    text = (folder / 'README.md').read_text()
    assert '2 laws x 2 configurations (published, tuned) x 3 draws' in text
    assert 'paired against pid/tuned' in text and 'envelope on' in text
    for label in ('pid/published', 'pid/tuned', 'luo_xu/published', 'luo_xu/tuned'):
        row = margins.set_index('law').loc[label]
        cell = campaign_report.margins_cell(row.to_dict())
        assert f'| {cell} |' in text and f'| {label} |' in text
    assert '| pid/tuned | ' in text and '(x1.00) | (baseline) |' in text


def test_one_row_is_made_again_in_its_configuration(tmp_path, capsys):
    path = write(tmp_path, dict(BOTH, draws=1, end_time_s=5))
    out = tmp_path / 'out'
    assert main(['--campaign', str(path), '--draw', '0', '--law', 'pid', '--configuration',
                 'tuned', '--out', str(out)]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert (shown['law'], shown['configuration']) == ('pid/tuned', 'tuned')
    assert main(['--campaign', str(path), '--draw', '0', '--law', 'pid/published', '--out',
                 str(out)]) == 0
    assert json.loads(capsys.readouterr().out)['configuration'] == 'published'
    assert main(['--campaign', str(path), '--draw', '0', '--law', 'pid', '--out',
                 str(out)]) == 2
    assert "'pid' runs in published, tuned: give --configuration" in capsys.readouterr().err
    published = write(tmp_path, dict(BOTH, draws=1, configurations=['published']), 'p.yaml')
    assert main(['--campaign', str(published), '--draw', '0', '--law', 'pid',
                 '--configuration', 'tuned', '--out', str(out)]) == 2
    assert '--configuration: the campaign runs published, not tuned' in capsys.readouterr().err
