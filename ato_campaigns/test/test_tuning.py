"""The tuning procedure (ato_campaigns.tuning) on a stand-in for the runs: its search space, its
score and constraints, the published start, the choice of the result, the artefact."""

import json
import math

import pytest

from ato_campaigns import tuning
from ato_campaigns.engine import load_campaign
from ato_common.validation import ConfigError
from ato_controller_node import gains


@pytest.fixture(scope='module')
def campaign():
    return load_campaign(tuning.DEFAULT_CAMPAIGN)


def row(rms=1.0, stop=0.1, energy=1000.0, atp=0.0, status='ok', law='pid', odometer=0.0):
    """A run's row; ``odometer``: the odometer's error at the stop (true stop error = the
    odometer stop error + it)."""
    return {'law': law, 'status': status, 'rms_speed_error_kmh': rms,
            'odometer_stop_error_m': stop, 'stop_error_m': stop + odometer,
            'traction_energy_kwh': energy, 'atp_interventions': atp}


def test_the_search_space_is_the_admissible_settings_negative_ranges_by_magnitude():
    pid = {d.name: d for d in tuning.search_space('pid')}
    assert set(pid) == {'kp_position', 'kd_speed', 'ki_position'}
    assert pid['kp_position'].bounds() == (0.01, 4.0) and pid['kp_position'].log
    am1 = next(d for d in tuning.search_space('tan_second_level_adaptive') if d.name == 'am1')
    assert am1.negative and am1.bounds() == (0.005, 1.0)
    assert am1.value(0.1) == -0.1 and am1.sampled(-0.1) == 0.1


def test_the_score_weighs_the_metrics_and_counts_the_violations():
    score = tuning.score([row(rms=1.0, stop=0.25, energy=500.0),
                          row(rms=3.0, stop=0.75, energy=1500.0, atp=2.0),
                          row(status='error', rms=math.nan)])
    # failed runs count 100 km/h; stops and energy over the runs with metrics
    assert score.objective == pytest.approx((1.0 + 3.0 + 100.0) / 3 + 0.5 / 0.5 + 1.0)
    assert score.violations == (1, 1, 1) and not score.feasible


def test_the_stop_is_judged_as_the_odometer_measured_it():
    """A draw whose odometer errs by 1.5 m at the stop puts every law's true stop 1.5 m off:
    the constraint and the objective read the part a law can act on; the truth is shown."""
    score = tuning.score([row(stop=0.1, odometer=1.5), row(stop=0.3)])
    assert score.feasible and score.objective == pytest.approx(1.0 + 0.2 / 0.5 + 1.0)
    assert score.metrics['stop_error_m'] == pytest.approx((1.6 + 0.3) / 2)
    assert tuning.score([row(stop=0.6)]).violations == (0, 1, 0)


def test_the_tuning_reads_the_default_campaign_for_its_published_start():
    """The default campaign names its configurations; the tuning reads it without the tuned
    one (it starts from the published settings, and a train without artefacts is tuned)."""
    campaign = load_campaign(tuning.DEFAULT_CAMPAIGN, configurations=('published',))
    assert campaign.configurations == ('published',) and campaign.tuned == {}
    assert {e.law for e in campaign.laws} == {e.law for e in load_campaign(
        tuning.DEFAULT_CAMPAIGN).laws}


def test_the_training_seed_must_not_be_the_campaigns(campaign):
    with pytest.raises(ConfigError, match=f"the training seed {campaign.seed} is the "
                                          "campaign's own"):
        tuning.training_campaign(campaign, campaign.seed, 2, ['pid'])
    training = tuning.training_campaign(campaign, 31, 2, ['pid'])
    assert (training.seed, training.draws) == (31, 2)


def stand_in(best_kp=0.3):
    """Runs that score a PID by how far kp is from ``best_kp``; kp above 1 brakes by the ATP."""
    def execute_runs(tasks, finished):
        for task in tasks:
            kp = task['settings']['kp_position']
            finished(row(rms=abs(math.log(kp / best_kp)), atp=float(kp > 1.0),
                         law=task['law']))
    return execute_runs


def test_the_procedure_starts_from_the_published_settings_and_keeps_the_best(campaign):
    searches = tuning.tune(campaign, ['pid'], trials=12, draws=2, execute_runs=stand_in(),
                           progress=False)
    (search,) = searches
    assert search.settings[0] == {'kp_position': 0.48, 'kd_speed': 1.2, 'ki_position': 0.064}
    number, best = search.best()
    assert best.feasible
    assert all(best.objective <= s.objective for s in search.scores.values() if s.feasible)
    again = tuning.tune(campaign, ['pid'], trials=12, draws=2, execute_runs=stand_in(),
                        progress=False)[0]
    assert again.settings == search.settings   # seeded: the same trials


def test_inadmissible_settings_are_not_run_and_count_as_failed(campaign):
    search = tuning.LawSearch.start('pid', 31)
    search.study.enqueue_trial({'kp_position': 0.02, 'kd_speed': 0.2, 'ki_position': 1.0})
    search.ask()   # the published start
    trial, settings = search.ask()
    assert settings is None and 'Routh-Hurwitz' in search.refused[trial.number]


def test_the_artefact_records_the_procedure_and_reads_back(campaign, tmp_path):
    search = tuning.tune(campaign, ['pid'], trials=3, draws=1, execute_runs=stand_in(),
                         progress=False)[0]
    from ato_campaigns.provenance import provenance
    record = tuning.artefact(search, campaign, 'short_line', 3, 1, 31, 12.0, provenance())
    (path,) = tuning.write_artefacts([record], tmp_path)
    assert path == tmp_path / 'crh3_luo_xu' / 'pid.json'
    read = gains.read_artefact(path)
    assert read.settings == search.settings[search.best()[0]]
    saved = json.loads(path.read_text())
    assert saved['budget'] == {'trials': 3, 'draws_per_trial': 1, 'runs': 3}
    assert saved['training']['seed'] == 31 and saved['procedure']['optuna']
    assert '| `pid` | crh3_luo_xu |' in tuning.summary_markdown([record], 12.0, 'this process')
