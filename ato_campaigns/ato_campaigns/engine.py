"""The campaign engine: every law of a campaign file on many draws of the uncertain train, on
Dask (the command line is ato_campaigns.campaign, the report ato_campaigns.report).

A campaign file (YAML) names the scenarios, the laws (optionally with gain overrides), the
uncertainty (ato_common.uncertainty), the number of draws and the seed::

    name: robustness
    seed: 1
    draws: 40
    scenarios: [short_line]          # built-in names or paths (relative to the campaign file)
    laws: [pid, {law: luo_xu_adaptive, settings: {gamma_a: 1.0e-4}},
           {law: pid, label: pid_flat, gradient: hidden}]  # its knowledge: a flat line
    baseline: pid                    # paired differences are taken against it
    uncertainty: default             # or nominal, or a mapping of parameters; if absent, each
                                     # scenario's uncertainty: section, else default
    timeout_s: 600                   # wall-time limit of one run
    end_time_s: 0                    # > 0: every run is the first end_time_s of its scenario

Every run is one (scenario, law, draw): the plant runs the truth perturbed by the draw, the
controller the knowledge of the nominal scenario (ato_simulation.loop). The runs go to a Dask
cluster: a LocalCluster of one single-threaded worker per core, or with ``--scheduler`` (or Dask's
``scheduler-address`` configuration, e.g. DASK_SCHEDULER_ADDRESS) a running cluster whose
workers run this project's environment; nothing else changes. ``--serial`` runs them in this
process, in order. Each finished run is written at once as a row of the Parquet dataset
``<out>/<name>/rows/``; a campaign started again with the same file runs only the rows that are
missing (a row of an earlier version of the file, with another fingerprint, does not count).
A run that raises is a row with status ``error`` and its reason; one that does not finish its
journey (``unfinished``: its state turns non-finite, or its train is not standing at a stop that
the reference stood at) ``diverged``; one that exceeds ``timeout_s`` ``timeout``: the campaign
goes on. A large speed or stop error alone is not a status: the metrics show it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import uuid
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ato_campaigns.run_process import RunDied, RunFailed, RunTimeout, limited
from ato_common import uncertainty
from ato_common.files import load_yaml
from ato_common.run_events import run_events, stations_of
from ato_common.scenario import Scenario, load_scenario
from ato_common.validation import ConfigError, Fields
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import setting_fields, validated_settings
from ato_simulation.applies import applicable_rate, plant_model_for

DEFAULT_OUT = Path('runs') / 'campaigns'
#: the default campaign of `make campaign`, shipped beside this module
DEFAULT_TIMEOUT_S = 600.0
#: stop accuracy of a platform stop (m): outside it a stop counts as a failure
STOP_ERROR_LIMIT_M = 0.5
#: a train at most this fast stands still (m/s; RunSupervision.STANDSTILL_MPS)
STANDSTILL_MPS = 0.01
#: the key of a row: which run it is
KEY = ('scenario', 'law', 'draw')
STATUSES = ('ok', 'diverged', 'error', 'timeout')
#: the per-run metrics every row has (NaN when the run did not produce them)
METRICS = ('rms_speed_error_kmh', 'max_speed_error_kmh', 'rms_position_error_m',
           'max_position_error_m', 'stop_error_m', 'arrival_error_s', 'traction_energy_kwh',
           'max_jerk_mps3', 'max_acceleration_mps2', 'saturated_fraction', 'atp_interventions',
           'watchdog_events')


#: what a law entry may say the controller is told of the gradient profile
GRADIENT_KNOWLEDGE = ('drawn', 'known', 'hidden')


@dataclass(frozen=True)
class LawEntry:
    label: str                      # the law's name in the rows (name, or name#k with settings)
    law: str
    settings: Mapping[str, Any] = field(default_factory=dict)
    #: the gradient profile in the controller's knowledge: as drawn (the uncertainty's
    #: gradient_known), or known or hidden in every draw of this entry
    gradient: str = 'drawn'


@dataclass(frozen=True)
class Campaign:
    name: str
    origin: str
    seed: int
    draws: int
    scenarios: tuple[str, ...]       # as load_scenario takes them (built-in name or abs path)
    laws: tuple[LawEntry, ...]
    #: the campaign file's uncertainty (None: it gives none, see ``specs``)
    spec: Mapping[str, uncertainty.Distribution] | None
    baseline: str
    timeout_s: float | None
    end_time_s: float | None
    rates_hz: Mapping[tuple[str, str], float] = field(default_factory=dict)
    models: Mapping[str, str] = field(default_factory=dict)
    #: the uncertainty each scenario is drawn from: the campaign file's, else the scenario's
    #: ``uncertainty:`` section, else uncertainty.DEFAULTS
    specs: Mapping[str, Mapping[str, uncertainty.Distribution]] = field(default_factory=dict)

    @property
    def fingerprint(self) -> str:
        """What the rows depend on: a row with another fingerprint is from another campaign."""
        text = json.dumps({'seed': self.seed, 'scenarios': self.scenarios,
                           'laws': [(e.label, e.law, dict(e.settings), e.gradient)
                                    for e in self.laws],
                           'spec': {scenario: {k: repr(v) for k, v in sorted(spec.items())}
                                    for scenario, spec in sorted(self.specs.items())},
                           'end_time_s': self.end_time_s}, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def tasks(self) -> list[dict]:
        """Every run of the campaign, draw-major (a partial campaign has whole draws)."""
        return [task_of(self, scenario, entry, index) for index in range(self.draws)
                for scenario in self.scenarios for entry in self.laws]


def task_of(campaign: Campaign, scenario: str, entry: LawEntry, index: int) -> dict:
    values = uncertainty.draw(campaign.specs[scenario], campaign.seed, index)
    if entry.gradient != 'drawn':  # a knowledge parameter: the plant of the draw is the same
        values['gradient_known'] = 1.0 if entry.gradient == 'known' else 0.0
    return {'campaign': campaign.name, 'fingerprint': campaign.fingerprint,
            'scenario': scenario, 'law': entry.label, 'law_name': entry.law,
            'settings': dict(entry.settings), 'draw': index, 'values': values,
            'model': campaign.models[scenario],
            'rate_hz': campaign.rates_hz[(scenario, entry.label)],
            'end_time_s': campaign.end_time_s, 'timeout_s': campaign.timeout_s}


# --- the campaign file --------------------------------------------------------------------------

def parse_campaign(data: Any, origin: str, base: Path) -> Campaign:
    """Validate a campaign; every error names ``origin`` and the field, before anything runs."""
    try:
        return _parse(data, origin, base)
    except ConfigError as error:
        raise ConfigError(f'{origin}: {error}') from None


def _parse(data: Any, origin: str, base: Path) -> Campaign:
    f = Fields(data, '')
    name = f.text('name')
    if not all(c.isalnum() or c in '-_.' for c in name):
        raise ConfigError(f'name: only letters, digits, - _ . (a folder name), got {name!r}')
    seed = int(f.number('seed', 0.0, minimum=0.0, maximum=2**31 - 1))
    draws = int(f.number('draws', 1.0, minimum=1.0, maximum=1e6))
    timeout = f.number('timeout_s', DEFAULT_TIMEOUT_S, minimum=0.0)
    end = f.number('end_time_s', 0.0, minimum=0.0)
    raw_scenarios = f.raw('scenarios', required=True)
    if not isinstance(raw_scenarios, list) or not raw_scenarios:
        raise ConfigError('scenarios: must be a non-empty list of scenario names or files')
    scenarios, loaded = [], {}
    for i, item in enumerate(raw_scenarios):
        if not isinstance(item, str):
            raise ConfigError(f'scenarios[{i}]: must be a scenario name or file, got {item!r}')
        path = base / item
        key = str(path.resolve()) if item.endswith(('.yaml', '.yml')) and path.is_file() else item
        try:
            loaded[key] = load_scenario(key)
        except ConfigError as error:
            raise ConfigError(f'scenarios[{i}]: {error}') from None
        scenarios.append(key)
    laws, labels = [], set()
    raw_laws = f.raw('laws', required=True)
    if raw_laws == 'all':
        raw_laws = sorted(LAWS)
    if not isinstance(raw_laws, list) or not raw_laws:
        raise ConfigError("laws: must be 'all' or a non-empty list of laws")
    for i, item in enumerate(raw_laws):
        laws.append(_law_entry(item, i))
    for i, entry in enumerate(laws):
        if entry.label in labels:
            raise ConfigError(f"laws[{i}]: the label '{entry.label}' is used twice")
        labels.add(entry.label)
    rates, models = {}, {}
    for key, scenario in loaded.items():
        models[key] = plant_model_for(scenario)
        for i, entry in enumerate(laws):
            rate, reason = applicable_rate(entry.law, scenario)
            if rate is None:
                raise ConfigError(f"laws[{i}]: {entry.law} does not fit scenario "
                                  f"'{scenario.name}': {reason}")
            rates[(key, entry.label)] = rate
    baseline = f.text('baseline', laws[0].label)
    if baseline not in labels:
        raise ConfigError(f"baseline: '{baseline}' is not one of the campaign's laws "
                          f"({', '.join(sorted(labels))})")
    raw_spec = f.raw('uncertainty')
    spec = None if raw_spec is None else uncertainty.parse_uncertainty(raw_spec)
    specs = {key: spec if spec is not None else scenario.uncertainty
             if scenario.uncertainty is not None else dict(uncertainty.DEFAULTS)
             for key, scenario in loaded.items()}
    f.reject_unknown()
    return Campaign(name, origin, seed, draws, tuple(scenarios), tuple(laws), spec, baseline,
                    timeout or None, end or None, rates, models, specs)


def _law_entry(item: Any, i: int) -> LawEntry:
    """``name`` or ``{law: name, settings: {gain: value}, label: text, gradient: hidden}``."""
    if isinstance(item, str):
        item = {'law': item}
    law_fields = Fields(item, f'laws[{i}]')
    law = law_fields.text('law')
    if law not in LAWS:
        raise ConfigError(f"laws[{i}].law: unknown law '{law}'; valid: {', '.join(LAWS)}")
    settings = law_fields.raw('settings') or {}
    if not isinstance(settings, Mapping):
        raise ConfigError(f'laws[{i}].settings: must be a mapping of settings of {law}')
    known = {s.name for s in setting_fields(LAWS[law].Settings)}
    for key in settings:
        if key not in known:
            raise ConfigError(f"laws[{i}].settings.{key}: not a setting of {law}; valid: "
                              f"{', '.join(sorted(known))}")
    try:
        validated_settings(LAWS[law].Settings, settings)
    except (ValueError, TypeError) as error:
        raise ConfigError(f'laws[{i}].settings: {error}') from None
    gradient = law_fields.text('gradient', 'drawn')
    if gradient not in GRADIENT_KNOWLEDGE:
        raise ConfigError(f"laws[{i}].gradient: '{gradient}' is not valid; valid: "
                          f"{', '.join(GRADIENT_KNOWLEDGE)}")
    default_label = law if not settings and gradient == 'drawn' else f'{law}#{i}'
    label = law_fields.text('label', default_label)
    law_fields.reject_unknown()
    return LawEntry(label, law, dict(settings), gradient)


def load_campaign(path: str | Path) -> Campaign:
    path = Path(path)
    return parse_campaign(load_yaml(path), str(path), path.parent)


# --- one run ------------------------------------------------------------------------------------

def base_row(task: Mapping) -> dict:
    row = {k: task[k] for k in ('campaign', 'fingerprint', 'scenario', 'law', 'law_name',
                                'draw', 'model', 'rate_hz')}
    row['settings'] = json.dumps(task['settings'], sort_keys=True)
    row.update({f'p_{k}': v for k, v in task['values'].items()})
    row.update({m: math.nan for m in METRICS})
    row.update(status='ok', reason='', stop_errors_m='{}', events='', wall_s=math.nan)
    return row


def run_task(task: Mapping, runner: Callable[[Mapping], dict] | None = None) -> dict:
    """One run of a campaign as a row; never raises (a failure is the row's status). On a Dask
    worker the run goes to the worker's run process (ato_campaigns.run_process)."""
    row = base_row(task)
    started = time.perf_counter()
    try:
        row.update(limited(partial(runner or offline_metrics, task), task['timeout_s']))
        why = row.pop('unfinished', '')
        if why:
            row.update(status='diverged', reason=f'did not finish: {why}')
    except RunTimeout:
        row.update(status='timeout', reason=f'exceeded the wall-time limit of '
                                            f'{task["timeout_s"]:g} s (timeout_s)')
    except (RunFailed, RunDied) as error:  # any failure of a law is a result to show
        row.update(status='error', reason=str(error))
    row['wall_s'] = time.perf_counter() - started
    return row


#: the scenarios this process has parsed, by name or path and file version (see
#: ``task_scenario``)
_SCENARIOS: dict[tuple, Scenario] = {}


def task_scenario(name_or_path: str) -> Scenario:
    """``load_scenario(name_or_path)``, parsed once per process and file version: a worker runs
    many draws and laws of the same few scenarios, and parsing one (YAML, validation, the line
    and the train) costs about 1 % of a run. A file is parsed again when its modification time
    or size changes (a long-lived cluster's workers see an edited scenario)."""
    path = Path(name_or_path)
    stat = path.stat() if name_or_path.endswith(('.yaml', '.yml')) and path.is_file() else None
    key = (name_or_path, stat and (stat.st_mtime_ns, stat.st_size))
    scenario = _SCENARIOS.get(key)
    if scenario is None:
        scenario = _SCENARIOS[key] = load_scenario(name_or_path)
    return scenario


def offline_metrics(task: Mapping) -> dict:
    """The offline closed loop of one task and its metrics (ato_simulation.loop)."""
    from ato_simulation.loop import run_offline
    scenario = task_scenario(task['scenario'])
    settings = {task['law_name']: task['settings']} if task['settings'] else None
    run = run_offline(scenario, task['law_name'], settings, model=task['model'],
                      controller_rate_hz=task['rate_hz'], end_time_s=task['end_time_s'],
                      uncertainty=task['values'])
    return run_metrics(run, 1.0 / task['rate_hz'])


def run_metrics(run, dt: float) -> dict:
    """The per-run metrics of an OfflineRun (METRICS); status diverged if it is not finite."""
    if not all(np.all(np.isfinite(a)) for a in (run.positions, run.speeds, run.forces)):
        return {'status': 'diverged', 'reason': 'non-finite state or force'}
    m = run.metrics()
    v = run.speeds
    acc = np.diff(v) / dt if v.size > 1 else np.zeros(1)
    jerk = np.diff(acc) / dt if acc.size > 1 else np.zeros(1)
    arrival = []
    for stop in run.plan.stops:
        if stop.arrival_s > run.times_s[-1]:
            continue
        mark = stop.station.position_m - STOP_ERROR_LIMIT_M  # first reach of the stop zone
        truth = np.flatnonzero(run.positions >= mark)
        ref = np.flatnonzero(run.ref_positions >= mark)
        if ref.size and stop.station.position_m > run.positions[0] + 1.0:
            arrival.append(run.times_s[truth[0]] - run.times_s[ref[0]] if truth.size
                           else math.nan)  # not reached within the run: the stop error says it
    stop_errors = m.stop_errors_m
    return {
        'unfinished': unfinished(run),
        'rms_speed_error_kmh': m.rms_speed_error_kmh,
        'max_speed_error_kmh': m.max_speed_error_kmh,
        'rms_position_error_m': m.rms_position_error_m,
        'max_position_error_m': m.max_position_error_m,
        'stop_error_m': max((abs(e) for e in stop_errors.values()), default=math.nan),
        'stop_errors_m': json.dumps(stop_errors),
        'arrival_error_s': (math.nan if not arrival or any(map(math.isnan, arrival))
                            else max(arrival, key=abs)),
        'traction_energy_kwh': m.traction_energy_kwh,
        'max_jerk_mps3': float(np.max(np.abs(jerk))),
        'max_acceleration_mps2': float(np.max(np.abs(acc))),
        'saturated_fraction': float(np.mean(run.saturated)) if run.saturated.size else 0.0,
        'atp_interventions': float(run.atp_interventions),
        'watchdog_events': float(run.watchdog_events),
        # what went wrong, with the first occurrence of each kind (ato_common.run_events)
        'events': events_of(run, m),
    }


def events_of(run, metrics) -> str:
    """What went wrong in an OfflineRun, each kind with its first occurrence (ATP
    interventions, missed windows, stopping errors beyond the platform tolerance;
    ``ato_common.run_events``), in brief."""
    return run_events(run.scenario, metrics, stations_of(run.plan), run.times_s, run.positions,
                      atp_times_s=run.atp_times_s).brief()


def unfinished(run) -> str:
    """Why the train of an OfflineRun did not finish its journey ('' if it did): at each stop
    the reference stood at within the run, the train must have stood still too, within its own
    length of the stop (at the platform: a stop error beyond +/-0.5 m is a failed stop, not an
    unfinished run); at the end, where the reference stands, the train must stand there."""
    standing = np.abs(run.speeds) <= STANDSTILL_MPS
    reach = run.scenario.train.length_m
    end = run.times_s[-1]
    for stop in run.plan.stops:
        x = stop.station.position_m
        if stop.arrival_s > end or x <= run.positions[0] + 1.0:
            continue  # not reached by the reference within the run, or the start
        if stop.departure_s <= end:
            near = standing & (np.abs(run.positions - x) <= reach)
            if not near.any():
                return (f'the train never stood within its length ({reach:g} m) of '
                        f'{stop.station.name} at {x:g} m')
        elif not (standing[-1] and abs(run.positions[-1] - x) <= reach):
            return (f'at the end the train is at {run.positions[-1]:.0f} m, '
                    f'{run.speeds[-1] * 3.6:.1f} km/h, not standing within its length '
                    f'({reach:g} m) of {stop.station.name} at {x:g} m')
    return ''


# --- the rows on disk ---------------------------------------------------------------------------

def rows_folder(out: Path, name: str) -> Path:
    return out / name / 'rows'


def write_row(folder: Path, row: dict) -> Path:
    """One finished row as a Parquet file of the dataset, written atomically (a temporary name,
    then a rename): an interrupted campaign leaves whole rows only."""
    import pandas as pd
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f'part-{row["draw"]:06d}-{uuid.uuid4().hex}.parquet'
    tmp = path.with_suffix('.tmp')
    pd.DataFrame([row]).to_parquet(tmp, index=False)
    os.replace(tmp, path)
    return path


def read_rows(folder: Path, fingerprint: str | None = None):
    """The dataset as a DataFrame (empty if none); only the rows of ``fingerprint`` if given,
    one per key and fingerprint (the latest written if a row was written twice)."""
    import pandas as pd
    files = sorted(folder.glob('*.parquet'), key=lambda p: (p.stat().st_mtime_ns, p.name)) \
        if folder.is_dir() else []
    if not files:
        return pd.DataFrame()
    table = pd.concat([pd.read_parquet(p) for p in files], ignore_index=True)
    if fingerprint is not None:
        table = table[table['fingerprint'] == fingerprint]
    return table.drop_duplicates([*KEY, 'fingerprint'], keep='last').sort_values(
        ['scenario', 'law', 'draw']).reset_index(drop=True)


def compact(folder: Path) -> None:
    """Merge the files of the dataset into one (after a complete campaign; the rows of other
    fingerprints are kept)."""
    files = sorted(folder.glob('part-*.parquet'))
    if len(files) < 2:
        return
    table = read_rows(folder)
    merged = folder / f'rows-{uuid.uuid4().hex}.parquet'
    tmp = merged.with_suffix('.tmp')
    table.to_parquet(tmp, index=False)
    os.replace(tmp, merged)
    for p in folder.glob('*.parquet'):
        if p != merged:
            p.unlink()


# --- the engine ---------------------------------------------------------------------------------

def missing(campaign: Campaign, folder: Path) -> list[dict]:
    done = read_rows(folder, campaign.fingerprint)
    keys = set() if done.empty else set(zip(done['scenario'], done['law'], done['draw']))
    return [t for t in campaign.tasks() if (t['scenario'], t['law'], t['draw']) not in keys]


def run_serial(items: Iterable, function: Callable[[Any], dict],
               finished: Callable[[dict], None]) -> None:
    for item in items:
        finished(function(item))


#: the Dask configuration of a LocalCluster (its scheduler, in this process, and its workers):
#: no statistical profiler (by default a worker samples the stack of its task thread every
#: 10 ms, each sample taking the interpreter lock from the run), the event loops' tick every
#: 1 s rather than 20 ms and the system monitor every 5 s rather than 0.5 s (each wake-up takes
#: the lock too; together they cost an idle worker about 4 % of a core, 1 % after). A cluster
#: started with the dask command line is given the same with the DASK_DISTRIBUTED__...
#: variables of docs/guide/campaigns.md
WORKER_SETTINGS = {'distributed.worker.profile.enabled': False,
                   'distributed.admin.tick.interval': '1s',
                   'distributed.admin.system-monitor.interval': '5s'}


def open_client(scheduler: str | None = None, workers: int | None = None,
                allowed_failures: int | None = None):
    """(client, cluster): a Dask client to ``scheduler`` (or Dask's ``scheduler-address``
    configuration; cluster None), else to a new LocalCluster of ``workers`` single-threaded
    worker processes (default: one per core). ``allowed_failures``: how often a run whose
    worker died is tried again (Dask's default: 3)."""
    import dask
    from distributed import Client, LocalCluster
    address = scheduler or dask.config.get('scheduler-address', None)
    if address:
        return Client(address, timeout='30s'), None
    settings = dict(WORKER_SETTINGS)
    if allowed_failures is not None:
        settings['distributed.scheduler.allowed-failures'] = allowed_failures
    # The scheduler serves HTTP even without a dashboard; ':0' takes a free port rather than
    # 8787, which another cluster on the machine may hold.
    with dask.config.set(settings):
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address=':0', silence_logs=40)
    return Client(cluster), cluster


def run_dask(client, items: list, function: Callable[[Any], dict],
             finished: Callable[[dict], None], lost: Callable[[Any, str], dict]) -> None:
    """``function(item)`` for every item on the cluster of ``client``; ``finished`` gets each
    row as it arrives. A run that the cluster itself loses (its worker died more often than
    Dask's allowed-failures) is ``lost(item, reason)``."""
    from distributed import as_completed
    futures = {client.submit(function, item, key=f'run-{uuid.uuid4().hex}', pure=False): item
               for item in items}
    try:
        for future in as_completed(futures):
            try:
                row = future.result()
            except Exception as error:  # noqa: BLE001 -- the cluster lost the run
                row = lost(futures[future], f'the cluster lost the run: '
                                            f'{type(error).__name__}: {error}')
            finished(row)
    finally:
        for future in futures:
            future.cancel()


def execute(items: list, function: Callable[[Any], dict], finished: Callable[[dict], None],
            lost: Callable[[Any, str], dict], *, serial: bool = False,
            scheduler: str | None = None, workers: int | None = None, client=None,
            allowed_failures: int | None = None) -> None:
    """Run ``function`` (module level: the workers import it) on every item, in this process
    (``serial``), on ``client``'s cluster, on a running scheduler or on a new LocalCluster."""
    if not items:
        return
    if serial:
        run_serial(items, function, finished)
        return
    own, cluster = (client, None) if client is not None else open_client(
        scheduler, workers, allowed_failures)
    try:
        run_dask(own, items, function, finished, lost)
    finally:
        if client is None:
            own.close()
            if cluster is not None:
                cluster.close()


def _lost_row(task: Mapping, reason: str) -> dict:
    return dict(base_row(task), status='error', reason=reason)


def run_campaign(campaign: Campaign, out: Path = DEFAULT_OUT, *, serial: bool = False,
                 scheduler: str | None = None, workers: int | None = None, client=None,
                 runner: Callable | None = None, progress: bool = True):
    """Run what is missing of ``campaign`` and return every row (a DataFrame)."""
    from tqdm import tqdm
    folder = rows_folder(out, campaign.name)
    pending_tasks = missing(campaign, folder)
    total = len(campaign.tasks())
    bar = tqdm(total=total, initial=total - len(pending_tasks), unit='run', disable=not progress,
               desc=campaign.name, dynamic_ncols=True, file=sys.stderr)

    def finished(row: dict) -> None:
        write_row(folder, row)
        bar.set_postfix_str(f'{row["law"]} draw {row["draw"]}: {row["status"]}', refresh=False)
        bar.update(1)

    function = run_task if runner is None else partial(run_task, runner=runner)
    try:
        execute(pending_tasks, function, finished, _lost_row, serial=serial, scheduler=scheduler,
                workers=workers, client=client)
    finally:
        bar.close()
    rows = read_rows(folder, campaign.fingerprint)
    if len(rows) == total:
        compact(folder)
    return rows
