"""tuning: the suite's one tuning procedure, the same for every law including the PID; its
results are the ``tuned`` configuration of ``ato_controller_node.gains``.

    python -m ato_campaigns.tuning [--campaign FILE] [--laws L ...] [--trials N] [--draws N]
                                   [--seed N] [--scheduler tcp://HOST:8786] [--workers N]
                                   [--serial] [--out DIR] [--results-page PAGE]

``make tune`` runs it with the defaults on the default campaign's scenario and laws.

Procedure. For each law, a search over its admissible settings (those declared with an
``admissible`` range: the ranges its paper's stability conditions allow, with the sampled loop's
where the paper has none; ``ato_controller_node.laws.base.setting``), log-uniform where declared
so, by Optuna's tree-structured Parzen estimator (``TPESampler``, multivariate, seeded), started
from the published settings (the first trial of every law). Each trial runs the law on the same
TRAINING draws: ``--draws`` draws of the campaign's uncertainty with the seed ``--seed``, which
the campaign's evaluation seed must differ from (it is refused if equal), through the campaign
engine's runs (``ato_campaigns.engine.run_task``: the offline closed loop, the ATO envelope on,
the time limit) on the Dask cluster. A trial is scored on the campaign's metrics:

    J = mean RMS speed error [km/h] + mean worst odometer stop error / 0.5 m
        + mean traction energy / 1000 kWh

(one platform tolerance of stop error weighs as 1 km/h of RMS speed error, and so does 1000 kWh,
about one run's traction energy on short_line: energy breaks ties between laws that track alike)
with hard constraints, passed to the sampler (``Trial.set_constraint``): no draw with an ATP
intervention, no odometer stop error outside the platform tolerance (+/-0.5 m), no run that
fails; a failed run counts 100 km/h. The stop is judged as the train's own odometer measured it
(``odometer_stop_error_m`` of ``ato_campaigns.engine``): a law stops where its odometer says the
stop is, so the odometer's drawn error at the stop is in the true stop error of every law alike
and no setting can remove it; judged on the truth, a draw whose odometer errs by more than the
tolerance would make every trial infeasible. Settings the law's joint stability condition
refuses (``ControlLaw.inadmissible``) are not run and count as infeasible. The result is the
best feasible trial, or if none is feasible the one with the fewest violations (said so in the
artefact). Every law gets the same budget: ``--trials`` trials of ``--draws`` runs each. The
trials of all laws are interleaved, one per law in each round, so the cluster always has every
law's runs to do.

Each law's result is written as ``<out>/<train>/<law>.json`` (``ato_controller_node.gains``):
the settings, the procedure and its budget, the seeds, the scenario and uncertainty, the score
and the metrics of the chosen trial on the training draws, the commit, date, machine and wall
time. The search is deterministic (seeded sampler, deterministic runs, trials told in order), so
the same command on the same commit writes the same settings.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ato_campaigns.engine import (
    STOP_ERROR_LIMIT_M,
    LawEntry,
    base_row,
    execute,
    load_campaign,
    open_client,
    run_task,
    task_of,
)
from ato_campaigns.provenance import REPOSITORY, provenance, write_results_page
from ato_common.scenario import load_scenario
from ato_common.validation import ConfigError
from ato_controller_node import gains as gains_module
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import admissible_fields, validated_settings
from ato_simulation.applies import applicable_rate

DEFAULT_CAMPAIGN = Path(__file__).resolve().with_name('campaigns') / 'default.yaml'
#: the training seed: not the campaign's (2026), whose draws evaluate the result
TRAINING_SEED = 31
#: the budget of every law: trials, and training draws per trial
TRIALS = 40
DRAWS = 8
#: the sampler's random start before TPE models the results (the published settings first)
STARTUP_TRIALS = 10
#: the weights of the score: km/h of RMS speed error per (stop error / tolerance) and per kWh
STOP_WEIGHT_KMH = 1.0
ENERGY_SCALE_KWH = 1000.0
#: what a failed run (no metrics) counts, km/h
FAILED_RUN_KMH = 100.0


@dataclass(frozen=True)
class Dimension:
    """One admissible setting of a law as the sampler sees it: a float in [low, high], on a
    log scale if ``log``; a negative range is searched by its magnitude."""

    name: str
    low: float
    high: float
    log: bool

    @property
    def negative(self) -> bool:
        return self.high < 0.0

    def bounds(self) -> tuple[float, float]:
        """The sampler's range: the magnitudes of a negative range."""
        return (-self.high, -self.low) if self.negative else (self.low, self.high)

    def value(self, sampled: float) -> float:
        return -sampled if self.negative else sampled

    def sampled(self, value: float) -> float:
        return -value if self.negative else value


def search_space(law: str) -> list[Dimension]:
    """The admissible settings of ``law`` (its tuning search space)."""
    return [Dimension(f.name, f.metadata['admissible'][0], f.metadata['admissible'][1],
                      f.metadata['scale'] == 'log') for f in admissible_fields(LAWS[law].Settings)]


@dataclass(frozen=True)
class Score:
    """A trial's score on the training draws: the objective J and the hard constraints'
    violations (draws with an ATP intervention, stops outside the tolerance, failed runs)."""

    objective: float
    atp_draws: int
    stop_draws: int
    failed_draws: int
    metrics: Mapping[str, float] = field(default_factory=dict)

    @property
    def violations(self) -> tuple[int, int, int]:
        return (self.atp_draws, self.stop_draws, self.failed_draws)

    @property
    def feasible(self) -> bool:
        return not any(self.violations)


def _mean(values: list[float]) -> float:
    return math.fsum(values) / len(values) if values else math.nan


def score(rows: list[Mapping[str, Any]]) -> Score:
    """The score of one trial's runs (rows of ``engine.run_task``)."""
    rms, stops, energy, true_stops = [], [], [], []
    atp = stop_fail = failed = 0
    for row in rows:
        values = [row.get(k, math.nan) for k in ('rms_speed_error_kmh', 'odometer_stop_error_m',
                                                 'traction_energy_kwh')]
        if row.get('status') in ('error', 'timeout') or not all(map(math.isfinite, values)):
            failed += 1
            rms.append(FAILED_RUN_KMH)
            continue
        rms.append(values[0])
        stops.append(values[1])
        true_stops.append(row.get('stop_error_m', math.nan))
        energy.append(values[2])
        atp += row.get('atp_interventions', 0.0) > 0.0
        stop_fail += values[1] > STOP_ERROR_LIMIT_M
    objective = _mean(rms) + STOP_WEIGHT_KMH * (_mean(stops) / STOP_ERROR_LIMIT_M
                                                if stops else 0.0) \
        + (_mean(energy) / ENERGY_SCALE_KWH if energy else 0.0)
    metrics = {'rms_speed_error_kmh': _mean(rms), 'odometer_stop_error_m': _mean(stops),
               'stop_error_m': _mean([e for e in true_stops if math.isfinite(e)]),
               'traction_energy_kwh': _mean(energy), 'draws': float(len(rows))}
    return Score(objective, atp, stop_fail, failed, metrics)


#: the hard constraints, as Optuna's constraint names (a trial is feasible when all are 0)
CONSTRAINTS = ('atp_draws', 'stop_draws', 'failed_draws')


@dataclass
class LawSearch:
    """The study of one law: its space, its published start, its trials' settings."""

    law: str
    study: Any
    space: list[Dimension]
    settings: dict[int, dict[str, float]] = field(default_factory=dict)
    scores: dict[int, Score] = field(default_factory=dict)
    refused: dict[int, str] = field(default_factory=dict)

    @classmethod
    def start(cls, law: str, seed: int) -> 'LawSearch':
        import optuna
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        sampler = optuna.samplers.TPESampler(seed=seed, multivariate=True,
                                             n_startup_trials=STARTUP_TRIALS)
        study = optuna.create_study(direction='minimize', sampler=sampler,
                                    study_name=f'tune-{law}')
        space = search_space(law)
        published = LAWS[law].Settings()
        study.enqueue_trial({d.name: d.sampled(getattr(published, d.name)) for d in space})
        return cls(law, study, space)

    def ask(self):
        """The next trial and its settings (None if the law's joint condition refuses them)."""
        trial = self.study.ask()
        settings = {d.name: d.value(trial.suggest_float(d.name, *d.bounds(), log=d.log))
                    for d in self.space}
        self.settings[trial.number] = settings
        reason = LAWS[self.law].inadmissible(validated_settings(LAWS[self.law].Settings,
                                                                settings))
        if reason:
            self.refused[trial.number] = reason
        return trial, (None if reason else settings)

    def tell(self, trial, result: Score) -> None:
        for name, value in zip(CONSTRAINTS, result.violations):
            trial.set_constraint(name, float(value))
        self.scores[trial.number] = result
        self.study.tell(trial, result.objective)

    def best(self) -> tuple[int, Score]:
        """The best feasible trial, else the one with the fewest violations, then the lowest
        objective (ties: the earliest)."""
        return min(self.scores.items(), key=lambda item: (
            sum(item[1].violations), item[1].objective, item[0]))


def refused_score(draws: int) -> Score:
    return Score(FAILED_RUN_KMH, 0, 0, draws)


def training_campaign(campaign, seed: int, draws: int, laws: list[str]):
    """The campaign's scenario and uncertainty with the training seed and draws, and the
    control rate of each of ``laws`` on each scenario."""
    if seed == campaign.seed:
        raise ConfigError(f'the training seed {seed} is the campaign\'s own: the tuned gains '
                          'would be evaluated on the draws they were tuned on')
    rates = dict(campaign.rates_hz)
    for scenario in campaign.scenarios:
        for law in laws:
            rate, reason = applicable_rate(law, load_scenario(scenario))
            if rate is None:
                raise ConfigError(f'{law} does not fit {scenario}: {reason}')
            rates[(scenario, law)] = rate
    return dataclasses.replace(campaign, seed=seed, draws=draws, rates_hz=rates,
                               envelope=True)  # the procedure's, stated in each artefact


def run_round(training, searches: list[LawSearch], execute_runs) -> None:
    """One trial of every law: ask, run its training draws on the cluster, tell."""
    pending: dict[str, tuple[LawSearch, Any, list]] = {}
    tasks = []
    for search in searches:
        trial, settings = search.ask()
        if settings is None:
            search.tell(trial, refused_score(training.draws))
            continue
        entry = LawEntry(search.law, search.law, settings)
        for scenario in training.scenarios:
            for index in range(training.draws):
                task = task_of(training, scenario, entry, index)
                task['trial'] = (search.law, trial.number)
                tasks.append(task)
        pending[search.law] = (search, trial, [])
    execute_runs(tasks, lambda row: pending[row['law']][2].append(row))
    for search, trial, rows in pending.values():
        search.tell(trial, score(rows))


def tune(campaign, laws: list[str], trials: int = TRIALS, draws: int = DRAWS,
         seed: int = TRAINING_SEED, execute_runs=None, progress: bool = True
         ) -> list[LawSearch]:
    """Run the procedure for ``laws`` on ``campaign``'s scenario and uncertainty; return each
    law's search (``best()`` is the result). ``execute_runs(tasks, finished)`` runs a round's
    tasks (default: in this process, in order)."""
    from tqdm import tqdm
    training = training_campaign(campaign, seed, draws, laws)
    searches = [LawSearch.start(law, seed) for law in laws]
    runner = execute_runs or (lambda tasks, finished: execute(
        tasks, run_task, finished, _lost_row, serial=True))
    for _ in tqdm(range(trials), desc='tuning rounds', unit='round', disable=not progress,
                  file=sys.stderr, dynamic_ncols=True):
        run_round(training, searches, runner)
    return searches


def _lost_row(task: Mapping, reason: str) -> dict:
    return dict(base_row(task), status='error', reason=reason)


def artefact(search: LawSearch, campaign, scenario: str, trials: int, draws: int, seed: int,
             wall_s: float, measured) -> dict:
    """The tuned artefact of one law (``ato_controller_node.gains`` reads it)."""
    number, best = search.best()
    return {
        'format': gains_module.FORMAT,
        'law': search.law,
        'train': load_scenario(scenario).train.name,
        'configuration': 'tuned',
        'settings': search.settings[number],
        'procedure': {
            'command': 'make tune (python -m ato_campaigns.tuning)',
            'optimiser': 'Optuna TPESampler (multivariate; constraints by Trial.set_constraint)',
            'optuna': _optuna_version(),
            'startup_trials': STARTUP_TRIALS,
            'objective': 'mean RMS speed error [km/h] + mean worst odometer stop error / '
                         '0.5 m + mean traction energy / 1000 kWh',
            'constraints': 'no ATP intervention, odometer stop error within +/-0.5 m, no '
                           'failed run, on every training draw',
            'space': {d.name: [d.low, d.high, 'log' if d.log else 'linear']
                      for d in search.space},
            'first_trial': 'the published settings',
        },
        'budget': {'trials': trials, 'draws_per_trial': draws, 'runs': trials * draws},
        'training': {'campaign': _relative(campaign.origin), 'scenario': scenario, 'seed': seed,
                     'draws': draws, 'uncertainty': 'the campaign\'s',
                     'envelope': True, 'sampler_seed': seed},
        'result': {'trial': number, 'feasible': best.feasible,
                   'objective': best.objective,
                   'violations': dict(zip(CONSTRAINTS, best.violations)),
                   'training_metrics': dict(best.metrics),
                   'feasible_trials': sum(s.feasible for s in search.scores.values()),
                   'refused_trials': len(search.refused)},
        'produced': {'commit': measured.commit, 'date': measured.date_utc,
                     'machine': measured.machine, 'wall_s': round(wall_s, 1)},
    }


def _relative(path: str) -> str:
    """``path`` relative to the repository where it lies in it (an artefact names no machine)."""
    try:
        return str(Path(path).resolve().relative_to(REPOSITORY))
    except ValueError:
        return path


def _optuna_version() -> str:
    import optuna
    return optuna.__version__


def write_artefacts(records: list[dict], out: Path) -> list[Path]:
    paths = []
    for record in records:
        path = gains_module.artefact_path(record['law'], record['train'], out)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record, indent=1, sort_keys=False) + '\n')
        paths.append(path)
    return paths


def summary_markdown(records: list[dict], wall_s: float, workers: str) -> str:
    """The results page: the budget, the wall time and each law's result."""
    first = records[0]
    lines = [f"Budget: {first['budget']['trials']} trials x "
             f"{first['budget']['draws_per_trial']} training draws per law "
             f"({first['budget']['runs']} runs each), seed {first['training']['seed']}, "
             f"scenario {first['training']['scenario']}; the whole command took "
             f'{wall_s:.0f} s of wall time on {workers}.', '',
             '| law | train | draws with an ATP intervention / an odometer stop error outside '
             '+/-0.5 m / a failed run | objective | RMS speed error (km/h) | worst odometer stop '
             'error (m) | worst stop error (m) | energy (kWh) | settings |',
             '|---|---|---|---|---|---|---|---|---|']
    for r in records:
        res, m = r['result'], r['result']['training_metrics']
        settings = ', '.join(f'{k} {v:.4g}' for k, v in r['settings'].items())
        violations = ' / '.join(str(v) for v in res['violations'].values())
        lines.append(f"| `{r['law']}` | {r['train']} | {violations} | {res['objective']:.3f} | "
                     f"{m['rms_speed_error_kmh']:.3f} | {m['odometer_stop_error_m']:.3f} | "
                     f"{m['stop_error_m']:.3f} | "
                     f"{m['traction_energy_kwh']:.1f} | {settings} |")
    lines += ['', 'Metrics are the means over the training draws of the chosen trial. The '
              'stop is judged as the train\'s own odometer measured it (the law stops where its '
              'odometer says the stop is); the true stop error adds the odometer\'s drawn error '
              'there, the same for every law. The evaluation on the campaign\'s own draws is '
              '`make campaign`.']
    return '\n'.join(lines)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--campaign', type=Path, default=DEFAULT_CAMPAIGN,
                        help='the campaign whose scenario, laws and uncertainty are tuned for')
    parser.add_argument('--laws', nargs='+', default=None, choices=sorted(LAWS),
                        help="the laws (default: the campaign's)")
    parser.add_argument('--trials', type=int, default=TRIALS)
    parser.add_argument('--draws', type=int, default=DRAWS)
    parser.add_argument('--seed', type=int, default=TRAINING_SEED)
    parser.add_argument('--scheduler', default=None)
    parser.add_argument('--workers', type=int, default=None)
    parser.add_argument('--serial', action='store_true')
    parser.add_argument('--out', type=Path, default=gains_module.TUNED_DIR)
    parser.add_argument('--results-page', type=Path, default=None)
    args = parser.parse_args(argv)
    if args.trials < 1 or args.draws < 1:
        parser.error('--trials and --draws must be at least 1')
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        # its scenario, laws and uncertainty; the tuning starts from the published gains
        campaign = load_campaign(args.campaign, configurations=('published',))
        if len(campaign.scenarios) != 1:
            raise ConfigError(f'{args.campaign}: tuning needs a campaign of one scenario')
        laws = args.laws or list(dict.fromkeys(e.law for e in campaign.laws))
        training_campaign(campaign, args.seed, args.draws, laws)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    measured = provenance()
    started = time.monotonic()
    client = cluster = None
    if not args.serial:
        client, cluster = open_client(args.scheduler, args.workers)

    def runner(tasks, finished):
        execute(tasks, run_task, finished, _lost_row, serial=args.serial, client=client)

    try:
        searches = tune(campaign, laws, args.trials, args.draws, args.seed, runner)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    wall = time.monotonic() - started
    scenario = campaign.scenarios[0]
    records = [artefact(s, campaign, scenario, args.trials, args.draws, args.seed, wall,
                        measured) for s in searches]
    for path in write_artefacts(records, args.out):
        print(f'wrote {path}')
    if args.results_page is not None:
        workers = 'this process' if args.serial else (
            args.scheduler or f'a LocalCluster of {args.workers or "one worker per core"}')
        write_results_page(args.results_page, 'Tuning', 'make tune',
                           summary_markdown(records, wall, workers), measured)
        print(f'wrote {args.results_page}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
