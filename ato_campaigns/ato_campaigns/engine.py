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
``<out>/<name>/rows/`` (ato_campaigns.dataset: every file says in its metadata what its rows
stand on); a campaign started again with the same file runs only the rows that are missing. A
changed file (another seed, number of draws, law list, uncertainty or window: another
fingerprint) is refused in the folder of the earlier version, never mixed with its rows.
``rerun`` makes one row again, offline, in this process.

A row's status (``ato_common.run_events.STATUSES``) is ``ok`` only for a clean run whose train
finished its journey on time (no ATP intervention, every stop within the platform tolerance, no
missed time window, no held command, no late arrival); otherwise it names the most serious of
what went wrong and its reason lists each: ``error`` (the run raised), ``timeout`` (past
``timeout_s``), ``diverged`` (its state turned non-finite), ``did not finish`` (its train did not
stand at a stop the reference stood at, or at its last stop by the run's limit past the
timetable: ``ato_simulation.plans.JourneyEnd``), ``ATP intervention``, ``watchdog brake``,
``faults``, ``stop error``, ``late`` (an arrival ``LATE_AFTER_S`` or more after the timetable's),
``missed time window``. The campaign goes on whatever a run does.
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

from ato_campaigns.dataset import (
    check_folder,
    compact,
    read_rows,
    rows_folder,
    write_row,
)
from ato_campaigns.run_process import RunDied, RunFailed, RunTimeout, limited
from ato_common import uncertainty
from ato_common.files import load_yaml
from ato_common.run_events import (
    JOURNEY,
    LATE_AFTER_S,
    STATUSES,
    RunEvents,
    late_arrivals,
    merge,
    run_events,
    run_status,
    stations_of,
)
from ato_common.scenario import Scenario, load_scenario
from ato_common.validation import ConfigError, Fields
from ato_controller_node.gains import (
    GAINS,
    GainsUnavailable,
    TunedArtefact,
    available,
    tuned_artefact,
)
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
#: the per-run metrics every row has (NaN when the run did not produce them); the stop errors
#: signed as position minus stop: ``overshoot_m`` the largest beyond a stop, ``undershoot_m``
#: the largest short of one (0 when none), ``arrival_delay_s`` the latest arrival against the
#: timetable (negative: every stop early); ``odometer_stop_error_m`` the worst stop error as the
#: train's own odometer measured it (the part the law can act on: ``stop_error_m`` less the
#: odometer's error at the stop, ``OfflineRun.odometer_stop_errors_m``)
METRICS = ('rms_speed_error_kmh', 'max_speed_error_kmh', 'rms_position_error_m',
           'max_position_error_m', 'stop_error_m', 'overshoot_m', 'undershoot_m',
           'odometer_stop_error_m',
           'arrival_error_s', 'arrival_delay_s', 'traction_energy_kwh', 'max_jerk_mps3',
           'max_acceleration_mps2', 'saturated_fraction', 'atp_interventions',
           'watchdog_events')


#: what a law entry may say the controller is told of the gradient profile
GRADIENT_KNOWLEDGE = ('drawn', 'known', 'hidden')


#: the separator of a row's label: ``<entry>/<configuration>``, e.g. ``pid/tuned``
CONFIGURATION_SEPARATOR = '/'


@dataclass(frozen=True)
class LawEntry:
    #: the row's label: the entry's label and its configuration, ``pid/tuned`` (an entry
    #: built in code, e.g. by the tuning, may carry any label)
    label: str
    law: str
    #: the entry's own settings, on top of its configuration's (explicit overrides)
    settings: Mapping[str, Any] = field(default_factory=dict)
    #: the gradient profile in the controller's knowledge: as drawn (the uncertainty's
    #: gradient_known), or known or hidden in every draw of this entry
    gradient: str = 'drawn'
    #: the gains' configuration (``ato_controller_node.gains.GAINS``): the law's published
    #: settings, or its tuned artefact for the scenario's train
    configuration: str = 'published'
    #: the entry's label in the campaign file, without the configuration (``pid``)
    entry: str = ''


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
    #: the gains' configurations every law runs in, each on the same draws
    configurations: tuple[str, ...] = ('published',)
    #: the host's ATO envelope (ato_controller_node.envelope), on or off for every law
    envelope: bool = True
    #: the tuned artefact of each (scenario, law) run in the tuned configuration, read once
    #: when the file is read: every run of the campaign runs the same settings, whatever a
    #: worker's copy of the artefacts, and the fingerprint covers them
    tuned: Mapping[tuple[str, str], TunedArtefact] = field(default_factory=dict)

    def identity(self) -> dict[str, Any]:
        """What the rows depend on (JSON): the seed, the number of draws, the scenarios, the
        laws, their configurations and the tuned settings, the envelope, the uncertainty and
        the window."""
        return json.loads(json.dumps({
            'seed': self.seed, 'draws': self.draws, 'scenarios': list(self.scenarios),
            'laws': [[e.label, e.law, dict(e.settings), e.gradient] for e in self.laws],
            'configurations': list(self.configurations), 'envelope': self.envelope,
            'tuned': {f'{a.train}/{a.law}': dict(a.settings) for a in self.artefacts()},
            'spec': {scenario: {k: repr(v) for k, v in sorted(spec.items())}
                     for scenario, spec in sorted(self.specs.items())},
            'end_time_s': self.end_time_s}, sort_keys=True, default=str))

    def artefacts(self) -> list[TunedArtefact]:
        """The tuned artefacts the campaign runs, one per (train, law), sorted."""
        unique = {(a.train, a.law): a for a in self.tuned.values()}
        return [unique[key] for key in sorted(unique)]

    def settings_of(self, scenario: str, entry: LawEntry) -> dict[str, Any]:
        """The settings ``entry`` runs with on ``scenario``: its configuration's (none for
        ``published``: the law's defaults; the tuned artefact's for ``tuned``) with the entry's
        own on top."""
        base = self.tuned[(scenario, entry.law)].settings if entry.configuration == 'tuned' \
            else {}
        return {**base, **entry.settings}

    @property
    def fingerprint(self) -> str:
        """The hash of ``identity``: a row with another fingerprint is from another campaign
        (another seed, number of draws, law list, configuration, tuned gains, envelope,
        uncertainty or window)."""
        text = json.dumps(self.identity(), sort_keys=True)
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
            'configuration': entry.configuration, 'envelope': campaign.envelope,
            'settings': campaign.settings_of(scenario, entry), 'draw': index, 'values': values,
            'model': campaign.models[scenario],
            'rate_hz': campaign.rates_hz[(scenario, entry.label)],
            'end_time_s': campaign.end_time_s, 'timeout_s': campaign.timeout_s}


# --- the campaign file --------------------------------------------------------------------------

def parse_campaign(data: Any, origin: str, base: Path,
                   configurations: tuple[str, ...] | None = None) -> Campaign:
    """Validate a campaign; every error names ``origin`` and the field, before anything runs.
    ``configurations``: these instead of the file's (the tuning reads a campaign for its
    scenario, laws and uncertainty only: ``('published',)``)."""
    try:
        return _parse(data, origin, base, configurations)
    except ConfigError as error:
        raise ConfigError(f'{origin}: {error}') from None


def _parse(data: Any, origin: str, base: Path,
           configurations: tuple[str, ...] | None = None) -> Campaign:
    f = Fields(data, '')
    name = f.text('name')
    if not all(c.isalnum() or c in '-_.' for c in name):
        raise ConfigError(f'name: only letters, digits, - _ . (a folder name), got {name!r}')
    seed = _whole(f, 'seed', 0, 2**31 - 1)
    draws = _whole(f, 'draws', 1, 10**6, default=1)
    timeout = f.number('timeout_s', DEFAULT_TIMEOUT_S, minimum=0.0)
    end = f.number('end_time_s', 0.0, minimum=0.0)
    loaded = _scenarios(f, base)
    entries = _entries(f)
    chosen = _configurations(f)   # checked even when the caller replaces it
    chosen = chosen if configurations is None else tuple(configurations)
    envelope = _envelope(f)
    laws = tuple(LawEntry(f'{e.label}{CONFIGURATION_SEPARATOR}{c}', e.law, e.settings,
                          e.gradient, c, e.label) for e in entries for c in chosen)
    rates, models = {}, {}
    for key, scenario in loaded.items():
        models[key] = plant_model_for(scenario)
        for i, entry in enumerate(entries):
            rate, reason = applicable_rate(entry.law, scenario)
            if rate is None:
                raise ConfigError(f"laws[{i}]: {entry.law} does not fit scenario "
                                  f"'{scenario.name}': {reason}")
            rates.update({(key, law.label): rate for law in laws if law.entry == entry.label})
    tuned = _tuned(loaded, entries, seed) if 'tuned' in chosen else {}
    baseline = _baseline(f, entries, laws, chosen)
    raw_spec = f.raw('uncertainty')
    spec = None if raw_spec is None else uncertainty.parse_uncertainty(raw_spec)
    specs = {key: spec if spec is not None else scenario.uncertainty
             if scenario.uncertainty is not None else dict(uncertainty.DEFAULTS)
             for key, scenario in loaded.items()}
    f.reject_unknown()
    return Campaign(name, origin, seed, draws, tuple(loaded), laws, spec, baseline,
                    timeout or None, end or None, rates, models, specs, chosen, envelope, tuned)


def _scenarios(f: Fields, base: Path) -> dict[str, Scenario]:
    """The campaign's scenarios, loaded, by the key the tasks name them by (a built-in name
    or a file's absolute path)."""
    raw_scenarios = f.raw('scenarios', required=True)
    if not isinstance(raw_scenarios, list) or not raw_scenarios:
        raise ConfigError('scenarios: must be a non-empty list of scenario names or files')
    loaded = {}
    for i, item in enumerate(raw_scenarios):
        if not isinstance(item, str):
            raise ConfigError(f'scenarios[{i}]: must be a scenario name or file, got {item!r}')
        path = base / item
        key = str(path.resolve()) if item.endswith(('.yaml', '.yml')) and path.is_file() else item
        try:
            loaded[key] = load_scenario(key)
        except ConfigError as error:
            raise ConfigError(f'scenarios[{i}]: {error}') from None
    return loaded


def _entries(f: Fields) -> list[LawEntry]:
    """The file's law entries (before their configurations), each label once."""
    raw_laws = f.raw('laws', required=True)
    if raw_laws == 'all':
        raw_laws = sorted(LAWS)
    if not isinstance(raw_laws, list) or not raw_laws:
        raise ConfigError("laws: must be 'all' or a non-empty list of laws")
    entries = [_law_entry(item, i) for i, item in enumerate(raw_laws)]
    labels: set[str] = set()
    for i, entry in enumerate(entries):
        if entry.label in labels:
            raise ConfigError(f"laws[{i}]: the label '{entry.label}' is used twice")
        labels.add(entry.label)
    return entries


def _configurations(f: Fields) -> tuple[str, ...]:
    """``configurations:``, a list of GAINS (default: every one)."""
    raw = f.raw('configurations')
    if raw is None:
        return GAINS
    if isinstance(raw, str):
        raw = [raw]
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"configurations: must be a non-empty list of {', '.join(GAINS)}, "
                          f'got {raw!r}')
    for i, item in enumerate(raw):
        if item not in GAINS:
            raise ConfigError(f"configurations[{i}]: '{item}' is not valid; valid: "
                              f"{', '.join(GAINS)}")
    if len(set(raw)) != len(raw):
        raise ConfigError(f'configurations: each configuration once, got {raw!r}')
    return tuple(raw)


def _envelope(f: Fields) -> bool:
    """``envelope: on | off`` (YAML reads both as booleans; default on)."""
    raw = f.raw('envelope')
    if raw is None:
        return True
    if isinstance(raw, bool):
        return raw
    if raw in ('on', 'off'):
        return raw == 'on'
    raise ConfigError(f'envelope: must be on or off (the ATO envelope of every law), '
                      f'got {raw!r}')


def _tuned(loaded: Mapping[str, Scenario], entries: list[LawEntry], seed: int
           ) -> dict[tuple[str, str], TunedArtefact]:
    """The tuned artefact of every law on every scenario's train; a law without one, a
    malformed one, or one tuned on the campaign's own seed is refused, naming law and train
    (never a silent fallback to the published settings)."""
    tuned = {}
    for key, scenario in loaded.items():
        train = scenario.train.name
        for i, entry in enumerate(entries):
            try:
                artefact = tuned_artefact(entry.law, train)
            except GainsUnavailable:
                there = ', '.join(f'{law} on {on}' for on, law in available()) or 'none'
                raise ConfigError(f"laws[{i}]: {entry.law} has no tuned gains for the train "
                                  f"{train} of scenario '{scenario.name}' (tuned: {there}); run "
                                  'make tune for it, or the published configuration only: '
                                  'configurations: [published]') from None
            except ValueError as error:
                raise ConfigError(f'laws[{i}]: the tuned gains of {entry.law} for the train '
                                  f'{train}: {error}') from None
            training = artefact.record.get('training', {})
            if training.get('seed') == seed:
                raise ConfigError(f'seed: {seed} is the seed the tuned gains of {entry.law} '
                                  f'for the train {train} were trained on; evaluate them on '
                                  'draws the tuning never saw (another seed)')
            tuned[(key, entry.law)] = artefact
    return tuned


def _baseline(f: Fields, entries: list[LawEntry], laws: tuple[LawEntry, ...],
              configurations: tuple[str, ...]) -> str:
    """The label paired differences are taken against: ``baseline:`` as a row label
    (``pid/published``) or an entry's label, which takes the tuned configuration if the
    campaign runs it, else its first; default: the entry ``pid`` if there is one, else the
    first entry."""
    labels = [law.label for law in laws]
    default = 'pid' if any(e.label == 'pid' for e in entries) else entries[0].label
    given = f.text('baseline', default)
    if given in labels:
        return given
    preferred = 'tuned' if 'tuned' in configurations else configurations[0]
    if any(e.label == given for e in entries):
        return f'{given}{CONFIGURATION_SEPARATOR}{preferred}'
    raise ConfigError(f"baseline: '{given}' is not one of the campaign's laws "
                      f"({', '.join(labels)}; or an entry's label: "
                      f"{', '.join(e.label for e in entries)})")


def _whole(f: Fields, key: str, minimum: int, maximum: int, default: int = 0) -> int:
    """A whole number field (``draws: 2.5`` is refused, naming the field)."""
    value = f.number(key, float(default), minimum=float(minimum), maximum=float(maximum))
    if not value.is_integer():
        raise ConfigError(f'{key}: must be a whole number, got {value:g}')
    return int(value)


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
    if CONFIGURATION_SEPARATOR in label:
        raise ConfigError(f"laws[{i}].label: '{label}' has a '{CONFIGURATION_SEPARATOR}', "
                          'which separates a label from its configuration in the rows')
    law_fields.reject_unknown()
    return LawEntry(label, law, dict(settings), gradient, entry=label)


def load_campaign(path: str | Path, configurations: tuple[str, ...] | None = None
                  ) -> Campaign:
    """The campaign file ``path``, validated (``configurations``: see parse_campaign)."""
    path = Path(path)
    return parse_campaign(load_yaml(path), str(path), path.parent, configurations)


# --- one run ------------------------------------------------------------------------------------

def base_row(task: Mapping) -> dict:
    row = {k: task[k] for k in ('campaign', 'fingerprint', 'scenario', 'law', 'law_name',
                                'configuration', 'envelope', 'draw', 'model', 'rate_hz')}
    row['settings'] = json.dumps(task['settings'], sort_keys=True)
    row.update({f'p_{k}': v for k, v in task['values'].items()})
    row.update({m: math.nan for m in METRICS})
    row.update(status='', reason='', stop_errors_m='{}', events='', wall_s=math.nan)
    return row


def run_task(task: Mapping, runner: Callable[[Mapping], dict] | None = None) -> dict:
    """One run of a campaign as a row; never raises (a failure is the row's status). On a Dask
    worker the run goes to the worker's run process (ato_campaigns.run_process). ``runner``
    (default :func:`offline_metrics`) gives the row's metrics and its status."""
    row = base_row(task)
    started = time.perf_counter()
    try:
        result = limited(partial(runner or offline_metrics, task), task['timeout_s'])
        if result.get('status') not in STATUSES:
            result = dict(result, status='error',
                          reason=f'the run gave no valid status: {result.get("status")!r}')
        row.update(result)
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


def offline_run(task: Mapping):
    """The offline closed loop of one task (ato_simulation.loop): an OfflineRun. The task's
    settings are its configuration's, resolved when the campaign was read
    (``Campaign.settings_of``): on top of the law's defaults, i.e. ``gains='published'``."""
    from ato_simulation.loop import run_offline
    scenario = task_scenario(task['scenario'])
    settings = {task['law_name']: task['settings']} if task['settings'] else None
    return run_offline(scenario, task['law_name'], settings, model=task['model'],
                       controller_rate_hz=task['rate_hz'], end_time_s=task['end_time_s'],
                       uncertainty=task['values'], gains='published',
                       envelope=task['envelope'])


def offline_metrics(task: Mapping) -> dict:
    """The offline closed loop of one task, its metrics and its status."""
    return run_metrics(offline_run(task), 1.0 / task['rate_hz'])


def finite(run) -> bool:
    return all(np.all(np.isfinite(a)) for a in (run.positions, run.speeds, run.forces))


def motion(speeds: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """What the passengers feel of a run sampled every ``dt``: its acceleration and its jerk,
    by differences of the lead car's speed (a brake that holds a train at rest moves nobody,
    so neither is read from the forces)."""
    acc = np.diff(speeds) / dt if speeds.size > 1 else np.zeros(1)
    jerk = np.diff(acc) / dt if acc.size > 1 else np.zeros(1)
    return acc, jerk


def run_metrics(run, dt: float, watchdog: RunEvents | None = None) -> dict:
    """The per-run metrics of an OfflineRun (METRICS) and its status and reason (``judged``);
    status diverged if it is not finite. ``watchdog``: the plant's watchdog brakes of a run
    through the graph (an offline run has none: its controller answers every period)."""
    if not finite(run):
        return {'status': 'diverged', 'reason': 'non-finite state or force'}
    m = run.metrics()
    acc, jerk = motion(run.speeds, dt)
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
    odometer = run.odometer_stop_errors_m()
    return {
        **judged(run, m, watchdog),
        'rms_speed_error_kmh': m.rms_speed_error_kmh,
        'max_speed_error_kmh': m.max_speed_error_kmh,
        'rms_position_error_m': m.rms_position_error_m,
        'max_position_error_m': m.max_position_error_m,
        'stop_error_m': max((abs(e) for e in stop_errors.values()), default=math.nan),
        'overshoot_m': max((max(e, 0.0) for e in stop_errors.values()), default=math.nan),
        'undershoot_m': max((max(-e, 0.0) for e in stop_errors.values()), default=math.nan),
        'stop_errors_m': json.dumps(stop_errors),
        'odometer_stop_error_m': max((abs(e) for e in odometer.values()), default=math.nan),
        'arrival_error_s': (math.nan if not arrival or any(map(math.isnan, arrival))
                            else max(arrival, key=abs)),
        'traction_energy_kwh': m.traction_energy_kwh,
        'max_jerk_mps3': float(np.max(np.abs(jerk))),
        'max_acceleration_mps2': float(np.max(np.abs(acc))),
        'saturated_fraction': float(np.mean(run.saturated)) if run.saturated.size else 0.0,
        'atp_interventions': float(run.atp_interventions),
        'watchdog_events': float(run.watchdog_events),
    }


def judged(run, metrics, watchdog: RunEvents | None = None) -> dict:
    """What went wrong in a finite OfflineRun (``ato_common.run_events``): its ``status`` and
    ``reason`` (``run_status``: did not finish, each kind of event with its first occurrence,
    held commands, late arrivals), its ``events`` in brief, and ``arrival_delay_s``, its
    latest arrival against the timetable (the run's first plan; NaN if it stood at no stop).
    A run over a window of its scenario (a stated end before its plan's) is judged on what
    the window holds: the stops departed within it, the timing points reached in it."""
    end = run.times_s[-1]
    window = run.journey is None and end < run.final_plan.trajectory.end_time
    stations = [s for s in stations_of(run.plan) if not (window and s[2] > end)]
    events = run_events(run.scenario, metrics, stations, run.times_s, run.positions,
                        atp_times_s=run.atp_times_s)
    if watchdog is not None:
        events = merge(events, watchdog, tolerance_m=events.tolerance_m)
    if window:
        kept = tuple(e for e in events.events if not (e.kind == JOURNEY and math.isnan(e.time_s)))
        events = RunEvents(kept, dict(events.counts, **{JOURNEY: sum(
            e.kind == JOURNEY for e in kept)}), events.tolerance_m)
    why = unfinished(run)
    timetable = [(s.station.name, s.station.position_m, s.arrival_s) for s in run.plan.stops
                 if s.station.position_m > run.positions[0] + 1.0]  # not the start
    delays = late_arrivals(timetable, run.times_s, run.positions, run.speeds,
                           run.scenario.train.length_m, late_after_s=-math.inf)
    late = [] if why else [(name, d) for name, d in delays if d >= LATE_AFTER_S]
    status, reason = run_status(events, why, late, [f for f in run.faults if f])
    return {'status': status, 'reason': reason, 'events': events.brief(),
            'arrival_delay_s': max((d for _, d in delays), default=math.nan)}


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


def data_description(campaign: Campaign) -> dict[str, Any]:
    """What a campaign's rows stand on, for every Parquet file's metadata: the campaign, its
    identity and fingerprint, the seed, the configurations and the envelope, the uncertainty
    of each scenario (in words too), the run's end rule, the tuning artefacts its tuned rows'
    gains came from (``tuning_artefact``: one per law and train, empty without the tuned
    configuration) and the commit of the code."""
    from ato_campaigns.provenance import commit_description
    from ato_simulation import plans
    window = campaign.end_time_s is not None
    return {
        'campaign': campaign.name, 'origin': campaign.origin,
        'fingerprint': campaign.fingerprint, 'identity': campaign.identity(),
        'seed': campaign.seed, 'draws': campaign.draws,
        'configurations': list(campaign.configurations), 'envelope': campaign.envelope,
        'baseline': campaign.baseline,
        'uncertainty': {scenario: {name: spec[name].describe() for name in spec}
                        for scenario, spec in campaign.specs.items()},
        'run_end': {
            'rule': 'window' if window else 'journey',
            'text': (f'the first {campaign.end_time_s:g} s of the scenario' if window else
                     'the planned end (the timetable\'s end plus the settle time) if the train '
                     'then stands at its last stop, else once it has stood there for the '
                     'settle time, at most the limit past the timetable'),
            'end_time_s': campaign.end_time_s,
            'late_limit_share': plans.LATE_LIMIT_SHARE,
            'late_limit_min_s': plans.LATE_LIMIT_MIN_S, 'late_after_s': LATE_AFTER_S},
        'tuning_artefact': [artefact_description(a) for a in campaign.artefacts()],
        'commit': commit_description()}


def artefact_description(artefact: TunedArtefact) -> dict[str, Any]:
    """What a tuned artefact is (its law, train, settings, procedure, budget, training seed
    and draws, and the commit that produced it), as the rows' metadata names it."""
    record = artefact.record
    training, produced = record.get('training', {}), record.get('produced', {})
    from ato_campaigns.provenance import REPOSITORY
    path = artefact.path.resolve()
    return {'law': artefact.law, 'train': artefact.train, 'settings': dict(artefact.settings),
            'file': str(path.relative_to(REPOSITORY)) if path.is_relative_to(REPOSITORY)
            else str(path),
            'procedure': record.get('procedure', {}), 'budget': record.get('budget', {}),
            'seed': training.get('seed'), 'training': training,
            'result': {k: v for k, v in record.get('result', {}).items()
                       if k in ('feasible', 'violations', 'objective')},
            'commit': produced.get('commit'), 'date': produced.get('date')}


def run_campaign(campaign: Campaign, out: Path = DEFAULT_OUT, *, serial: bool = False,
                 scheduler: str | None = None, workers: int | None = None, client=None,
                 runner: Callable | None = None, progress: bool = True):
    """Run what is missing of ``campaign`` and return every row (a DataFrame). A folder that
    holds the rows of another version of the campaign is refused (FolderConflict)."""
    from tqdm import tqdm
    folder = rows_folder(out, campaign.name)
    check_folder(folder, campaign.fingerprint, campaign.identity())
    description = data_description(campaign)
    pending_tasks = missing(campaign, folder)
    total = len(campaign.tasks())
    bar = tqdm(total=total, initial=total - len(pending_tasks), unit='run', disable=not progress,
               desc=campaign.name, dynamic_ncols=True, file=sys.stderr)

    def finished(row: dict) -> None:
        write_row(folder, row, description)
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
        compact(folder, description)
    return rows


def rerun(campaign: Campaign, law: str, draw: int, scenario: str | None = None,
          configuration: str | None = None):
    """One row of ``campaign`` made again offline, in this process, exactly as the campaign
    made it (the same task: draw, settings, rate, window, envelope), without its time limit:
    (the row, the OfflineRun). ``law``: the row's label (``pid/tuned``), or with
    ``configuration`` its entry's label (``pid``); ``scenario``: a campaign of several
    scenarios needs it (a name or a file as the campaign gives it)."""
    key = _scenario_of(campaign, scenario)
    entry = _entry_of(campaign, law, configuration)
    if not 0 <= draw < campaign.draws:
        raise ConfigError(f'--draw: the campaign has draws 0 to {campaign.draws - 1}, '
                          f'not {draw}')
    task = task_of(campaign, key, entry, draw)
    row = base_row(task)
    started = time.perf_counter()
    run = offline_run(task)
    row.update(run_metrics(run, 1.0 / task['rate_hz']), wall_s=time.perf_counter() - started)
    return row, run


def _entry_of(campaign: Campaign, law: str, configuration: str | None) -> LawEntry:
    """The law entry of a row named by its label, or by its entry's label and configuration
    (the configuration may be left out when the campaign runs one)."""
    if configuration is not None and configuration not in campaign.configurations:
        raise ConfigError(f'--configuration: the campaign runs '
                          f"{', '.join(campaign.configurations)}, not {configuration}")
    fits = [e for e in campaign.laws if configuration in (None, e.configuration)]
    found = [e for e in fits if e.label == law] or [e for e in fits if e.entry == law]
    if len(found) == 1:
        return found[0]
    labels = ', '.join(e.label for e in campaign.laws)
    if found:
        raise ConfigError(f"--law: '{law}' runs in {', '.join(e.configuration for e in found)}"
                          f': give --configuration, or a label ({labels})')
    raise ConfigError(f"--law: '{law}'" + (f' in {configuration}' if configuration else '')
                      + f' is not a law of the campaign; its laws: {labels}')


def _scenario_of(campaign: Campaign, scenario: str | None) -> str:
    if scenario is None:
        if len(campaign.scenarios) > 1:
            raise ConfigError('--scenario: the campaign has several scenarios: '
                              + ', '.join(campaign.scenarios))
        return campaign.scenarios[0]
    for key in campaign.scenarios:
        if scenario in (key, Path(key).name, Path(key).stem):
            return key
    raise ConfigError(f"--scenario: '{scenario}' is not a scenario of the campaign; its "
                      f"scenarios: {', '.join(campaign.scenarios)}")
