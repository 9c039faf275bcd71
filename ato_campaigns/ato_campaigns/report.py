"""The report of a campaign: ``<out>/<name>/report.md``, its PNG plots, and every statistic of
it as CSV (``<out>/<name>/stats/<table>.csv``) and JSON (``<out>/<name>/report.json``), from
the rows (ato_campaigns.stats computes them; this module lays them out).

Per scenario: a warning when fewer than ``stats.MIN_PAIRS`` draws are paired; the ranking by
RMS speed error (saying which laws cannot be told apart from the best); an overview per law (its
statuses, its failure rates, its means, and any per-law columns a caller adds: ``law_columns``);
the distribution of each metric (mean, median, p95, worst over the runs with metrics); the
signed stop errors per stop (over- and undershoot apart); the failure rates with Wilson
intervals; the paired failure comparison with the baseline (Newcombe intervals, McNemar's exact
test); the paired differences with the baseline (mean, median, p95, each with its bootstrap
interval); the Pareto view of error, energy and stop accuracy; the parameters that drive each
law's RMS speed error and stop error (Spearman); the runs that were not ok; and the plots: box
plots of the metrics per law, the empirical CDF of the stop error, the error against the most
influential parameter, the Pareto view and the convergence of the main estimates with the
number of draws. A row of the tables is a law label of the campaign (a law, or a law in one of
its configurations).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ato_campaigns import stats as cs
from ato_campaigns.engine import STOP_ERROR_LIMIT_M, Campaign, artefact_description
from ato_campaigns.margins import largest_actuator
from ato_campaigns.provenance import write_results_page
from ato_common import uncertainty
from ato_common.run_events import LATE_AFTER_S, STATUSES

#: the metric the ranking, the convergence and the sensitivity use
RANK_METRIC = 'rms_speed_error_kmh'
TABLE_METRICS = (('rms_speed_error_kmh', 'RMS speed error (km/h)', '.3f'),
                 ('max_speed_error_kmh', 'max speed error (km/h)', '.3f'),
                 ('rms_position_error_m', 'RMS position error (m)', '.3f'),
                 ('stop_error_m', 'worst stop error (m)', '.3f'),
                 ('overshoot_m', 'largest overshoot of a stop (m)', '.3f'),
                 ('undershoot_m', 'largest undershoot of a stop (m)', '.3f'),
                 ('odometer_stop_error_m', 'worst stop error by the odometer (m)', '.3f'),
                 ('arrival_error_s', 'arrival-time error (s)', '.2f'),
                 ('arrival_delay_s', 'latest arrival against the timetable (s)', '.1f'),
                 ('traction_energy_kwh', 'traction energy (kWh)', '.1f'),
                 ('max_jerk_mps3', 'max jerk (m/s^3)', '.2f'),
                 ('max_acceleration_mps2', 'max acceleration (m/s^2)', '.3f'),
                 ('saturated_fraction', 'share of steps saturated', '.3f'),
                 ('atp_interventions', 'ATP interventions', '.2f'),
                 ('watchdog_events', 'watchdog periods', '.2f'))
LABELS = {metric: label for metric, label, _ in TABLE_METRICS}
FORMATS = {metric: fmt for metric, _, fmt in TABLE_METRICS}
#: the metrics whose paired differences with the baseline the report shows
PAIRED_METRICS = ('rms_speed_error_kmh', 'max_speed_error_kmh', 'rms_position_error_m',
                  'stop_error_m', 'arrival_delay_s', 'traction_energy_kwh', 'max_jerk_mps3')
#: the metrics whose drivers the report names
SENSITIVITY_METRICS = ('rms_speed_error_kmh', 'stop_error_m')
BOX_METRICS = ('rms_speed_error_kmh', 'stop_error_m', 'traction_energy_kwh', 'max_jerk_mps3')
#: the failure kinds of the overview and the README's summary
OVERVIEW_KINDS = ('not ok', 'did not finish', 'late', 'ATP intervention', cs.STOP_KIND,
                  cs.ODOMETER_STOP_KIND)


def _f(value: Any, fmt: str) -> str:
    return '-' if value is None or (isinstance(value, float) and math.isnan(value)) \
        else format(value, fmt)


def scenario_name(key: str) -> str:
    return Path(key).stem if key.endswith(('.yaml', '.yml')) else key


def _metrics(rows, metrics) -> list[str]:
    """The metrics of ``metrics`` the rows have (rows of an older version may lack some)."""
    return [m for m in metrics if m in rows.columns]


# --- every statistic, as tables --------------------------------------------------------------

def _stacked(frames: dict[str, Any], column: str):
    import pandas as pd
    parts = [frame.assign(**{column: key}) for key, frame in frames.items() if not frame.empty]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def overview(campaign: Campaign, rows, law_columns=None):
    """Per (scenario, law): its runs, its status counts, the rate of each OVERVIEW_KINDS, the
    mean RMS speed error and traction energy, and the columns of ``law_columns`` (a DataFrame
    indexed by law label, or with columns ``scenario`` and ``law``: e.g. a law's
    configuration or its loop margins) joined by law (and scenario)."""
    import pandas as pd
    rates = cs.failure_rates(rows).set_index(['scenario', 'law', 'kind'])
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        counts = group['status'].value_counts()
        record = {'scenario': scenario, 'law': law, 'runs': len(group),
                  'statuses': ', '.join(f'{counts[s]} {s}' for s in STATUSES if s in counts)}
        for kind in OVERVIEW_KINDS:
            r = rates.loc[(scenario, law, kind)]
            record.update({f'{kind}: k': int(r['k']), f'{kind}: low': r['low'],
                           f'{kind}: high': r['high']})
        measured = group[group['status'].isin(cs.MEASURED)]
        for metric in _metrics(rows, (RANK_METRIC, 'traction_energy_kwh')):
            record[f'mean {metric}'] = float(measured[metric].mean())
        out.append(record)
    table = pd.DataFrame(out)
    if law_columns is not None and not table.empty and not law_columns.empty:
        if 'scenario' in law_columns.columns:   # per scenario and label (e.g. the margins)
            table = table.merge(law_columns, on=['scenario', 'law'], how='left')
        else:
            table = table.join(law_columns, on='law')
    return table


def statistics(campaign: Campaign, rows, law_columns=None) -> dict[str, Any]:
    """Every table of the report (all scenarios; a ``scenario`` column in each), by name."""
    metrics = _metrics(rows, [m for m, _, _ in TABLE_METRICS])
    ranking = [(key, rank, law, mean, apart) for key in campaign.scenarios
               for rank, (law, mean, apart) in enumerate(
                   cs.ranking(rows, key, RANK_METRIC) if RANK_METRIC in rows else [], 1)]
    import pandas as pd
    return {
        'overview': overview(campaign, rows, law_columns),
        'ranking': pd.DataFrame(ranking, columns=['scenario', 'rank', 'law', 'mean',
                                                  'told_apart_from_best']),
        'metrics': _stacked({m: cs.summary(rows, m) for m in metrics}, 'metric'),
        'signed_stop_errors': cs.signed_stop_errors(rows),
        'failure_rates': cs.failure_rates(rows),
        'paired_failures': cs.paired_failures(rows, campaign.baseline),
        'paired_differences': _stacked({m: cs.paired_differences(rows, campaign.baseline, m)
                                        for m in _metrics(rows, PAIRED_METRICS)}, 'metric'),
        'pareto': cs.pareto(rows, tuple(_metrics(rows, cs.PARETO_METRICS))),
        'convergence': cs.convergence(rows, RANK_METRIC),
        'sensitivity': _stacked({m: cs.sensitivity(rows, m)
                                 for m in _metrics(rows, SENSITIVITY_METRICS)}, 'metric'),
        'margins': _margins_frame(law_columns),
        'tuned_vs_published': tuned_vs_published(campaign, rows),
    }


def tuned_vs_published(campaign: Campaign, rows):
    """What the tuning changes, per scenario and law entry run in both configurations, on the
    same draws: the paired differences tuned minus published of the main metrics (with their
    bootstrap intervals) and of the rate of ATP interventions and of runs not ok (Newcombe
    interval, McNemar's exact p-value)."""
    import pandas as pd
    parts = []
    pairs: dict[str, dict[str, str]] = {}
    for e in campaign.laws:
        pairs.setdefault(e.entry, {})[e.configuration] = e.label
    for entry, labels in pairs.items():
        if not {'published', 'tuned'} <= set(labels):
            continue
        sub = rows[rows['law'].isin([labels['published'], labels['tuned']])]
        for metric in _metrics(rows, (RANK_METRIC, 'stop_error_m', 'traction_energy_kwh')):
            d = cs.paired_differences(sub, labels['published'], metric)
            parts.append(d.assign(entry=entry, metric=metric, kind=''))
        failures = cs.paired_failures(sub, labels['published'])
        failures = failures[failures['kind'].isin(('ATP intervention', 'not ok'))]
        parts.append(failures.rename(columns={'rate_diff': 'mean_diff'}).assign(
            entry=entry, metric='rate'))
    if not parts:
        return pd.DataFrame()
    table = pd.concat(parts, ignore_index=True)
    first = ['scenario', 'entry', 'law', 'baseline', 'metric', 'kind', 'pairs', 'mean_diff',
             'low', 'high']
    return table[first + [c for c in table.columns if c not in first]]


def _margins_frame(law_columns):
    """The loop margins of every label (``law_columns`` when it holds them), else empty."""
    import pandas as pd
    if law_columns is None or 'note' not in law_columns.columns:
        return pd.DataFrame()
    frame = law_columns if 'scenario' in law_columns.columns else \
        law_columns.rename_axis('law').reset_index()
    return frame.reset_index(drop=True)


def methods() -> dict[str, Any]:
    """How the statistics were made (stated in the report and its JSON)."""
    return {'confidence': cs.CONFIDENCE, 'bootstrap_method': cs.BOOTSTRAP_METHOD,
            'bootstrap_resamples': cs.BOOTSTRAP_RESAMPLES, 'bootstrap_seed': cs.BOOTSTRAP_SEED,
            'min_pairs': cs.MIN_PAIRS, 'spearman_exact_max_n': cs.SPEARMAN_EXACT_MAX_N,
            'stop_tolerance_m': STOP_ERROR_LIMIT_M, 'late_after_s': LATE_AFTER_S,
            'proportion_interval': 'Wilson score',
            'paired_proportion_interval': 'Newcombe (1998) method 10',
            'paired_failure_test': "McNemar's exact (binomial) test"}


def _records(frame) -> list[dict]:
    """A table as JSON records: NaN and infinities as null, numpy scalars as Python's."""
    records = json.loads(frame.to_json(orient='records', double_precision=15))
    return records


def write_statistics(campaign: Campaign, tables: dict[str, Any], folder: Path,
                     command: str) -> Path:
    """Each table as ``<folder>/stats/<name>.csv``, all of them and the methods as
    ``<folder>/report.json``."""
    stats_folder = folder / 'stats'
    stats_folder.mkdir(parents=True, exist_ok=True)
    for name, table in tables.items():
        table.to_csv(stats_folder / f'{name}.csv', index=False)
    path = folder / 'report.json'
    path.write_text(json.dumps({
        'campaign': campaign.name, 'origin': campaign.origin,
        'fingerprint': campaign.fingerprint, 'seed': campaign.seed, 'draws': campaign.draws,
        'baseline': campaign.baseline, 'configurations': list(campaign.configurations),
        'envelope': campaign.envelope,
        'tuning_artefacts': [artefact_description(a) for a in campaign.artefacts()],
        'command': command, 'methods': methods(),
        'tables': {name: _records(table) for name, table in tables.items()}}, indent=1))
    return path


# --- the markdown ------------------------------------------------------------------------------

#: how a campaign's own rows are run (rows without a ``through`` column)
OFFLINE = 'offline closed loop'


def how_run(rows) -> str:
    """How the rows were run, from their own ``through`` column (rows made another way than
    the campaign's offline loop say how, e.g. through the ROS graph; a row without it is the
    offline loop's); each way with its laws when the rows were run in several."""
    if 'through' not in rows.columns or rows.empty:
        return OFFLINE
    ways = rows['through'].fillna(OFFLINE)
    kinds = sorted(set(ways))
    if len(kinds) == 1:
        return kinds[0]
    return '; '.join(f"{kind} ({', '.join(sorted(set(rows.loc[ways == kind, 'law'])))})"
                     for kind in kinds)


def _header(campaign: Campaign, rows, elapsed_s: float) -> list[str]:
    runs = len(rows)
    statuses = rows['status'].value_counts().to_dict() if runs else {}
    counted = ', '.join(f'{statuses[s]} {s}' for s in STATUSES if s in statuses)
    m = methods()
    entries = len({e.entry or e.label for e in campaign.laws})
    return [f'Campaign `{campaign.name}` ({campaign.origin}): {len(campaign.scenarios)} '
            f'scenario(s) x {entries} laws x {len(campaign.configurations)} configuration(s) '
            f'({", ".join(campaign.configurations)}) x {campaign.draws} draws, seed '
            f'{campaign.seed}, fingerprint `{campaign.fingerprint}`: {runs} runs ({counted}); '
            f'the runs took {rows["wall_s"].sum():.0f} s in sum, this command {elapsed_s:.0f} s '
            f'of wall time on {os.cpu_count()} cores (a resumed campaign runs only the missing '
            f'rows); {how_run(rows)}, the plant perturbed by each draw, the controller on the '
            'nominal train. A run is `ok` only when it is clean and punctual: it finished its '
            'journey, with no ATP intervention, every stop within '
            f'+/-{STOP_ERROR_LIMIT_M:g} m, no missed time window and no arrival '
            f'{LATE_AFTER_S:g} s or more after the timetable; otherwise its status names the most '
            'serious of what went wrong (the order of the statuses above) and its reason each.',
            '', *_gains(campaign), '## Methods', '',
            f'- Intervals at {m["confidence"]:.0%}. Proportions: Wilson score intervals. Paired '
            'failure comparison: the difference of the two laws\' rates on the same draws with '
            "Newcombe's hybrid score interval for paired proportions (Newcombe 1998, method 10) "
            "and McNemar's exact test (the binomial test of the discordant pairs).",
            f'- Paired differences (law minus baseline on the draws both ran): the mean '
            'difference, the difference of the medians and the difference of the 95th '
            f'percentiles, each with a paired {m["bootstrap_method"]} bootstrap interval '
            f'(scipy.stats.bootstrap, {m["bootstrap_resamples"]} resamples, seed '
            f'{m["bootstrap_seed"]}).',
            f'- Below {m["min_pairs"]} pairs a section warns, and no law is told apart from '
            'another: a percentile bootstrap interval is too narrow at small n.',
            f'- Spearman p-values: exact (every pairing of the ranks, '
            f'scipy.stats.permutation_test) up to {m["spearman_exact_max_n"]} runs, the t '
            'approximation (scipy.stats.spearmanr) above.',
            '- Every table is also in `stats/<table>.csv` and `report.json` beside this '
            'report.', '']


def _gains(campaign: Campaign) -> list[str]:
    """The configurations, the envelope, the baseline and the tuned artefacts."""
    envelope = 'on' if campaign.envelope else 'off'
    lines = ['## Gains, envelope, baseline', '',
             f'Every law runs in each configuration of its gains on the same draws, as its own '
             f'row `<law>/<configuration>`: {", ".join(campaign.configurations)} '
             '(`published`: the paper\'s law and gains; `tuned`: the gains of the suite\'s one '
             'tuning procedure, `make tune`, the same for every law). The ATO envelope of the '
             f'controller host (anti-windup of the position and speed errors) is {envelope} for '
             f'every law. Paired comparisons are taken against **{campaign.baseline}** (the '
             "campaign's `baseline`; by default the PID, in its tuned configuration when the "
             'campaign runs it).', '']
    artefacts = campaign.artefacts()
    if artefacts:
        lines += ['| law | train | training seed, draws | budget | feasible on its training '
                  'draws | produced at commit | file |', '|---|---|---|---|---|---|---|']
        for a in map(artefact_description, artefacts):
            budget, result = a['budget'], a['result']
            lines.append(f"| {a['law']} | {a['train']} | {a['seed']}, "
                         f"{a['training'].get('draws', '-')} on "
                         f"{a['training'].get('scenario', '-')} | {budget.get('trials', '-')} "
                         f"trials x {budget.get('draws_per_trial', '-')} draws | "
                         f"{'yes' if result.get('feasible') else 'no'} | {a['commit']} | "
                         f"`{a['file']}` |")
        lines.append('')
    return lines


def _uncertainty(campaign: Campaign) -> list[str]:
    lines = ['## Uncertainty', '']
    specs = [(key, campaign.specs[key]) for key in campaign.scenarios]
    if all(spec == specs[0][1] for _, spec in specs):
        specs = specs[:1]  # one for every scenario
    for key, spec in specs:
        if len(specs) > 1:
            lines += [f'Scenario `{scenario_name(key)}` (its own `uncertainty:` section, or the '
                      'defaults):', '']
        lines += ['| parameter | unit | distribution | source |', '|---|---|---|---|']
        for name, unit, dist, source in uncertainty.describe(spec):
            lines.append(f'| `{name}` | {unit} | {dist} | {source} |')
        lines.append('')
    return lines


def _pairs_warning(sub, key: str) -> list[str]:
    pairs = cs.fewest_pairs(sub, key, RANK_METRIC)
    if pairs >= cs.MIN_PAIRS or sub['law'].nunique() < 2:
        return []
    return [f'**Warning: only {pairs} paired draws** (fewer than {cs.MIN_PAIRS}): the '
            'intervals below are too narrow to rely on and no law is told apart from another; '
            'run more draws.', '']


def _ranking_line(sub, key: str) -> list[str]:
    ranked = cs.ranking(sub, key, RANK_METRIC)
    if not ranked:
        return []
    best = ranked[0][0]
    tied = [law for law, _, apart in ranked[1:] if not apart]
    order = ' < '.join(f'{law} ({mean:.3f})' for law, mean, _ in ranked)
    verdict = (f'; cannot be told apart from it at {cs.CONFIDENCE:.0%} (paired bootstrap '
               f'interval contains 0, or fewer than {cs.MIN_PAIRS} pairs): ' + ', '.join(tied)
               if tied else f'; every other law is told apart from it at {cs.CONFIDENCE:.0%}')
    return [f'Ranking by mean RMS speed error over the runs with metrics (km/h): {order}. '
            f'Best: **{best}**{verdict}.', '']


def margins_cell(r: dict) -> str:
    """A label's loop margins in brief: phase and delay margin on the nominal plant, and its
    stability at the campaign's largest actuator draw (``-`` without margins)."""
    pm = r.get('phase_margin_deg')
    if pm is None or (isinstance(pm, float) and math.isnan(pm)):
        return '-'
    nominal = (f"{_f(pm, '.0f')} deg, {_f(r.get('delay_margin_s'), '.2g')} s"
               if r.get('stable_nominal') else 'unstable')
    worst = 'stable' if r.get('covers_actuator_draws') else 'unstable'
    return f'{nominal}; {worst}'


def _overview_table(table, key: str) -> list[str]:
    sub = table[table['scenario'] == key]
    extra = [c for c in ('configuration',) if c in sub.columns]
    margins = 'phase_margin_deg' in sub.columns
    lines = ['### Overview', '',
             '| law | statuses | ' + ' | '.join(f'{kind} [CI]' for kind in OVERVIEW_KINDS)
             + ' | mean RMS speed error (km/h) | mean traction energy (kWh) | '
             + ''.join(f'{c} | ' for c in extra)
             + ('loop margins: phase, delay (nominal); at the largest actuator | '
                if margins else ''),
             '|---|---|' + '---|' * (len(OVERVIEW_KINDS) + 2 + len(extra) + margins)]
    for r in sub.to_dict('records'):
        cells = [f'{r[f"{k}: k"]}/{r["runs"]} [{_f(r[f"{k}: low"], ".2f")}, '
                 f'{_f(r[f"{k}: high"], ".2f")}]' for k in OVERVIEW_KINDS]
        lines.append(f'| {r["law"]} | {r["statuses"]} | ' + ' | '.join(cells)
                     + f' | {_f(r.get(f"mean {RANK_METRIC}"), ".3f")} | '
                     + f'{_f(r.get("mean traction_energy_kwh"), ".1f")} | '
                     + ''.join(f'{r[c]} | ' for c in extra)
                     + (f'{margins_cell(r)} |' if margins else ''))
    return lines + ['']


def _margins_section(campaign: Campaign, tables: dict, key: str) -> list[str]:
    """Each label's loop margins (ato_campaigns.margins) with the settings it ran, and a
    sentence for each that cannot cover the campaign's actuator draws."""
    table = tables['margins']
    table = table[table['scenario'] == key] if 'scenario' in table.columns else table
    if table.empty:
        return []
    try:
        worst = largest_actuator(campaign.specs[key]).describe()
    except (ValueError, KeyError) as error:
        worst = f'none ({error})'
    lines = ['### Loop margins (the loop linearised about cruise with the settings each row '
             'ran: ato_campaigns.margins, python-control)', '',
             'Phase and delay margin on the nominal plant (the controller\'s hold, no '
             'actuator) and whether the loop is stable there; the same at the campaign\'s '
             f'largest actuator draw ({worst}), and the largest dead time the loop tolerates '
             'with that lag. An adaptive law is linearised with its adaptation frozen at its '
             'nominal estimates.', '',
             '| law | configuration | phase margin (deg) | delay margin (s) | stable, nominal '
             '| phase margin at the largest actuator (deg) | stable there | largest dead time '
             'tolerated (s) |', '|---|---|---|---|---|---|---|---|']
    said = []
    for r in table.to_dict('records'):
        if not isinstance(r.get('phase_margin_deg'), float) or \
                math.isnan(r['phase_margin_deg']):
            lines.append(f"| {r['law']} | {r.get('configuration', '-')} | - | - | - | - | - "
                         '| - |')
            said.append(f"- `{r['law']}`: {r['note']}.")
            continue
        covers = bool(r['covers_actuator_draws'])
        lines.append(f"| {r['law']} | {r.get('configuration', '-')} | "
                     f"{_f(r['phase_margin_deg'], '.1f')} | {_f(r['delay_margin_s'], '.3g')} | "
                     f"{'yes' if r['stable_nominal'] else 'no'} | "
                     f"{_f(r['worst_phase_margin_deg'], '.1f')} | "
                     f"{'yes' if covers else 'no'} | {_f(r['tolerated_dead_time_s'], '.3g')} |")
        if not covers:
            said.append(f"- `{r['law']}`: its loop {r['coverage']}.")
    return lines + [''] + (said + [''] if said else [])


def _metrics_table(campaign: Campaign, tables: dict, key: str) -> list[str]:
    labels = [e.label for e in campaign.laws]
    lines = ['### Metrics (the runs with metrics: mean / median / p95 / worst)', '',
             '| metric | ' + ' | '.join(labels) + ' |', '|---|' + '---|' * len(labels)]
    metrics = tables['metrics']
    metrics = metrics[metrics['scenario'] == key] if not metrics.empty else metrics
    for metric, label, fmt in TABLE_METRICS:
        table = metrics[metrics['metric'] == metric].set_index('law') \
            if not metrics.empty else metrics
        if table.empty:
            continue
        cells = ['-' if law not in table.index else ' / '.join(
            _f(table.loc[law, c], fmt) for c in ('mean', 'median', 'p95', 'worst'))
            for law in labels]
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return lines + ['']


def _stop_table(tables: dict, key: str) -> list[str]:
    table = tables['signed_stop_errors']
    table = table[table['scenario'] == key] if not table.empty else table
    lines = [f'### Signed stop errors (position minus stop, m: positive an overshoot; over- '
             f'and undershoots beyond +/-{STOP_ERROR_LIMIT_M:g} m counted apart)', '',
             '| law | stop | runs | mean | median | p5 | p95 | overshoots | undershoots |',
             '|---|---|---|---|---|---|---|---|---|']
    for r in table.itertuples():
        lines.append(f'| {r.law} | {r.stop} | {r.n} | {r.mean:+.3f} | {r.median:+.3f} | '
                     f'{r.p5:+.3f} | {r.p95:+.3f} | {r.overshoots} | {r.undershoots} |')
    return lines + ['']


def _failure_tables(campaign: Campaign, tables: dict, key: str) -> list[str]:
    rates = tables['failure_rates']
    lines = [f'### Failure rates ({cs.CONFIDENCE:.0%} Wilson intervals)', '',
             '| law | kind | k / n | rate | interval |', '|---|---|---|---|---|']
    for r in rates[rates['scenario'] == key].itertuples():
        lines.append(f'| {r.law} | {r.kind} | {r.k} / {r.n} | {r.rate:.3f} | '
                     f'[{r.low:.3f}, {r.high:.3f}] |')
    paired = tables['paired_failures']
    lines += ['', f'### Paired failures against {campaign.baseline} (same draws: both, the law '
              f'only, {campaign.baseline} only; rate difference law minus '
              f'{campaign.baseline} with its {cs.CONFIDENCE:.0%} Newcombe interval; McNemar\'s '
              'exact p-value)', '',
              '| law | kind | pairs | both / law only / baseline only | rate difference | '
              'interval | McNemar p |', '|---|---|---|---|---|---|---|']
    paired = paired[paired['scenario'] == key] if not paired.empty else paired
    for r in paired.itertuples():
        lines.append(f'| {r.law} | {r.kind} | {r.pairs} | {r.both} / {r.law_only} / '
                     f'{r.baseline_only} | {_f(r.rate_diff, "+.3f")} | [{_f(r.low, "+.3f")}, '
                     f'{_f(r.high, "+.3f")}] | {_f(r.mcnemar_p, ".3g")} |')
    return lines + ['']


def _paired_table(campaign: Campaign, tables: dict, key: str) -> list[str]:
    table = tables['paired_differences']
    lines = [f'### Paired differences against {campaign.baseline} (law minus '
             f'{campaign.baseline} on the same draws; {cs.CONFIDENCE:.0%} paired '
             f'{cs.BOOTSTRAP_METHOD} bootstrap intervals, {cs.BOOTSTRAP_RESAMPLES} resamples)',
             '', '| law | metric | pairs | mean difference [CI] | difference of medians [CI] | '
             'difference of p95 [CI] |', '|---|---|---|---|---|---|']
    table = table[table['scenario'] == key] if not table.empty else table
    for r in table.itertuples():
        fmt = '+' + FORMATS[r.metric]
        cells = [f'{_f(getattr(r, f"{s}_diff"), fmt)} [{_f(getattr(r, lo), fmt)}, '
                 f'{_f(getattr(r, hi), fmt)}]' for s, lo, hi in (
                     ('mean', 'low', 'high'), ('median', 'median_low', 'median_high'),
                     ('p95', 'p95_low', 'p95_high'))]
        lines.append(f'| {r.law} | {LABELS[r.metric]} | {r.pairs} | ' + ' | '.join(cells)
                     + ' |')
    return lines + ['']


def _tuned_table(tables: dict, key: str) -> list[str]:
    """What the tuning changes, per law (tuned_vs_published)."""
    table = tables['tuned_vs_published']
    table = table[table['scenario'] == key] if not table.empty else table
    if table.empty:
        return []
    lines = ['### Tuned against published (each law on the same draws: tuned minus published; '
             f'{cs.CONFIDENCE:.0%} paired bootstrap interval of the mean difference, for the '
             "rates Newcombe's interval and McNemar's exact p-value)", '',
             '| law | pairs | RMS speed error (km/h) | worst stop error (m) | traction energy '
             '(kWh) | ATP intervention rate | not ok rate | McNemar p (ATP, not ok) |',
             '|---|---|---|---|---|---|---|---|']
    for entry, group in table.groupby('entry', sort=False):
        cells, p_values = [str(group['pairs'].max())], []
        for metric, kind in ((RANK_METRIC, ''), ('stop_error_m', ''),
                             ('traction_energy_kwh', ''), ('rate', 'ATP intervention'),
                             ('rate', 'not ok')):
            r = group[(group['metric'] == metric) & (group['kind'] == kind)]
            if r.empty:
                cells.append('-')
                continue
            r = r.iloc[0]
            fmt = '+.3f' if metric != 'traction_energy_kwh' else '+.1f'
            cells.append(f'{_f(r["mean_diff"], fmt)} [{_f(r["low"], fmt)}, '
                         f'{_f(r["high"], fmt)}]')
            if metric == 'rate':
                p_values.append(_f(r.get('mcnemar_p'), '.3g'))
        lines.append(f'| {entry} | ' + ' | '.join(cells) + f' | {", ".join(p_values)} |')
    return lines + ['']


def _pareto_table(tables: dict, key: str) -> list[str]:
    table = tables['pareto']
    table = table[table['scenario'] == key] if not table.empty else table
    metrics = [m for m in cs.PARETO_METRICS if m in table.columns]
    lines = ['### Pareto view (mean over the runs with metrics; lower is better in each; a law '
             'is on the front when no other is at least as good in all and better in one)', '',
             '| law | ' + ' | '.join(LABELS[m] for m in metrics) + ' | on the front | '
             'dominated by |', '|---|' + '---|' * (len(metrics) + 2)]
    for r in table.to_dict('records'):
        lines.append(f'| {r["law"]} | ' + ' | '.join(_f(r[m], FORMATS[m]) for m in metrics)
                     + f' | {"yes" if not r["dominated_by"] else "no"} | '
                     + f'{r["dominated_by"] or "-"} |')
    return lines + ['']


def _sensitivity_tables(campaign: Campaign, tables: dict, key: str) -> list[str]:
    lines = []
    table = tables['sensitivity']
    for metric in SENSITIVITY_METRICS:
        sens = table[(table['scenario'] == key) & (table['metric'] == metric)] \
            if not table.empty else table
        lines += [f'### What drives the {LABELS[metric].split(" (")[0]} (Spearman rank '
                  'correlation, the 3 strongest per law; p-value exact or t)', '',
                  '| law | parameter | rho | p-value | n |', '|---|---|---|---|---|']
        for e in campaign.laws:
            for r in sens[sens['law'] == e.label].head(3).itertuples() if not sens.empty \
                    else ():
                lines.append(f'| {r.law} | `{r.parameter}` | {r.rho:+.2f} | '
                             f'{r.p_value:.2g} ({r.p_method}) | {r.n} |')
        lines.append('')
    return lines


def _not_ok(sub, shown: int = 20) -> list[str]:
    failed = sub[sub['status'] != 'ok']
    if not len(failed):
        return []
    lines = ['### Runs that were not ok', '', '| law | draw | status | reason |',
             '|---|---|---|---|']
    for r in failed.head(shown).itertuples():
        lines.append(f'| {r.law} | {r.draw} | {r.status} | '
                     f'{str(r.reason).replace("|", "/")} |')
    if len(failed) > shown:
        lines.append(f'| ... | | | {len(failed) - shown} more (the rows hold every one) |')
    return lines + ['']


PLOTS = ('metrics', 'stop_ecdf', 'sensitivity', 'pareto', 'convergence')


def _scenario_section(campaign: Campaign, rows, tables: dict, key: str,
                      plots: bool) -> list[str]:
    name = scenario_name(key)
    sub = rows[rows['scenario'] == key]
    if sub.empty:
        return []
    lines = [f'## {name}', '', *_pairs_warning(sub, key), *_ranking_line(sub, key),
             *_overview_table(tables['overview'], key),
             *_margins_section(campaign, tables, key),
             *_metrics_table(campaign, tables, key), *_stop_table(tables, key),
             *_failure_tables(campaign, tables, key), *_paired_table(campaign, tables, key),
             *_tuned_table(tables, key),
             *_pareto_table(tables, key), *_sensitivity_tables(campaign, tables, key),
             *_not_ok(sub)]
    if plots:
        for kind in PLOTS:
            lines += [f'![{kind}]({name}_{kind}.png)', '']
    return lines


def markdown(campaign: Campaign, rows, command: str, elapsed_s: float, plots: bool = True,
             tables: dict | None = None) -> str:
    """The report's body (``tables``: ``statistics(campaign, rows)``, computed if None)."""
    tables = statistics(campaign, rows) if tables is None else tables
    lines = [*_header(campaign, rows, elapsed_s), *_uncertainty(campaign)]
    for key in campaign.scenarios:
        lines += _scenario_section(campaign, rows, tables, key, plots)
    return '\n'.join(lines)


# --- the plots ---------------------------------------------------------------------------------

def _box_plot(plt, campaign: Campaign, ok, name: str, labels: list[str], folder: Path) -> Path:
    fig, axes = plt.subplots(1, len(BOX_METRICS), figsize=(4 * len(BOX_METRICS), 4))
    for ax, metric in zip(axes, BOX_METRICS):
        data = [ok[ok['law'] == law][metric].dropna().to_numpy() for law in labels]
        ax.boxplot(data, showmeans=True)
        ax.set_xticks(range(1, len(labels) + 1), labels, rotation=30, ha='right', fontsize=8)
        ax.set_title(LABELS[metric], fontsize=10)
    fig.suptitle(f'{name}: {campaign.draws} draws per law')
    return _save(fig, folder / f'{name}_metrics.png', plt)


def _stop_plot(plt, ok, name: str, labels: list[str], folder: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7, 4))
    for law in labels:
        e = np.sort(ok[ok['law'] == law]['stop_error_m'].dropna().to_numpy())
        if e.size:
            ax.step(e, np.arange(1, e.size + 1) / e.size, where='post', label=law)
    ax.axvline(STOP_ERROR_LIMIT_M, color='k', ls='--', lw=1, label=f'+/-{STOP_ERROR_LIMIT_M:g} m')
    ax.set(xscale='log', xlabel='worst |stop error| of the run (m)', ylabel='share of runs',
           title=f'{name}: empirical CDF of the stop error')
    ax.legend(fontsize=8)
    return _save(fig, folder / f'{name}_stop_ecdf.png', plt)


def _sensitivity_plot(plt, tables: dict, key: str, ok, name: str, labels: list[str],
                      folder: Path) -> Path:
    sens = tables['sensitivity']
    sens = sens[(sens['scenario'] == key) & (sens['metric'] == RANK_METRIC)] \
        if not sens.empty else sens
    fig, axes = plt.subplots(1, len(labels), figsize=(3.6 * len(labels), 3.4), squeeze=False)
    for ax, law in zip(axes[0], labels):
        top = sens[sens['law'] == law].head(1) if not sens.empty else sens
        mine = ok[ok['law'] == law]
        if top.empty:
            ax.text(0.5, 0.5, 'no varying parameter', ha='center', transform=ax.transAxes)
        else:
            p = top['parameter'].iloc[0]
            ax.scatter(mine[f'p_{p}'], mine[RANK_METRIC], s=10)
            ax.set(xlabel=f'{p} ({uncertainty.PARAMETERS[p].unit})',
                   title=f'{law}: rho {top["rho"].iloc[0]:+.2f}')
        ax.set_ylabel('RMS speed error (km/h)')
    fig.suptitle(f'{name}: error against the most influential parameter')
    return _save(fig, folder / f'{name}_sensitivity.png', plt)


def _pareto_plot(plt, tables: dict, key: str, name: str, folder: Path) -> Path:
    table = tables['pareto']
    table = table[table['scenario'] == key] if not table.empty else table
    fig, ax = plt.subplots(figsize=(7, 4.5))
    if not table.empty and {'rms_speed_error_kmh', 'traction_energy_kwh',
                            'stop_error_m'} <= set(table.columns):
        front = (table['dominated_by'] == '').to_numpy()
        stop = table['stop_error_m'].to_numpy(dtype=float)
        for finite in (True, False):  # a law without a stop (a window): grey
            kept = np.isfinite(stop) == finite
            if not kept.any():
                continue
            colour = {'c': stop[kept], 'cmap': 'viridis'} if finite else {'color': 'tab:gray'}
            points = ax.scatter(table['rms_speed_error_kmh'][kept],
                                table['traction_energy_kwh'][kept], **colour,
                                s=np.where(front[kept], 90, 40),
                                edgecolors=np.where(front[kept], 'k', 'none'))
            if finite:
                fig.colorbar(points, ax=ax, label='mean worst stop error (m)')
        for r in table.itertuples():
            ax.annotate(r.law, (r.rms_speed_error_kmh, r.traction_energy_kwh), fontsize=8,
                        xytext=(4, 4), textcoords='offset points')
    ax.set(xlabel='mean RMS speed error (km/h)', ylabel='mean traction energy (kWh)',
           title=f'{name}: Pareto view (outlined: on the front)')
    return _save(fig, folder / f'{name}_pareto.png', plt)


def _convergence_plot(plt, tables: dict, key: str, name: str, labels: list[str],
                      folder: Path) -> Path:
    table = tables['convergence']
    table = table[table['scenario'] == key] if not table.empty else table
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for law in labels:
        mine = table[table['law'] == law] if not table.empty else table
        if mine.empty:
            continue
        line, = top.plot(mine['draws'], mine['mean'], label=law)
        top.fill_between(mine['draws'], mine['mean_low'], mine['mean_high'], alpha=0.2,
                         color=line.get_color())
        bottom.plot(mine['draws'], mine['not_ok_rate'], color=line.get_color())
        bottom.fill_between(mine['draws'], mine['not_ok_low'], mine['not_ok_high'], alpha=0.2,
                            color=line.get_color())
    top.set(ylabel='mean RMS speed error (km/h)',
            title=f'{name}: the estimates over the first n draws ({cs.CONFIDENCE:.0%} '
                  'intervals)')
    bottom.set(xlabel='draws', ylabel='share of runs not ok', ylim=(-0.02, 1.02))
    top.legend(fontsize=8)
    return _save(fig, folder / f'{name}_convergence.png', plt)


def plot(campaign: Campaign, rows, folder: Path, tables: dict | None = None) -> list[Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    tables = statistics(campaign, rows) if tables is None else tables
    paths = []
    labels = [e.label for e in campaign.laws]
    for key in campaign.scenarios:
        name = scenario_name(key)
        ok = rows[(rows['scenario'] == key) & rows['status'].isin(cs.MEASURED)]
        if ok.empty:
            continue
        paths += [_box_plot(plt, campaign, ok, name, labels, folder),
                  _stop_plot(plt, ok, name, labels, folder),
                  _sensitivity_plot(plt, tables, key, ok, name, labels, folder),
                  _pareto_plot(plt, tables, key, name, folder),
                  _convergence_plot(plt, tables, key, name, labels, folder)]
    return paths


def _save(fig, path: Path, plt) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


# --- the README's summary and the files -------------------------------------------------------

README_START = '<!-- campaign summary: written by make campaign, do not edit -->'
README_END = '<!-- end of the campaign summary -->'


def summary_markdown(campaign: Campaign, rows, command: str, law_columns=None) -> str:
    """The short summary the README shows: per scenario, each row label (every law in each
    configuration, in the campaign's order) with its mean RMS speed error and its ratio to the
    baseline's, its paired difference against the baseline, its ATP interventions and runs
    not ok, and its loop margins in brief (``law_columns``: campaign_margins)."""
    entries = len(campaign.laws) // max(len(campaign.configurations), 1)
    lines = [f'`{command}`: {entries} laws x {len(campaign.configurations)} configurations '
             f'({", ".join(campaign.configurations)}) x {campaign.draws} draws of the default '
             f'uncertainty, seed {campaign.seed}, the ATO envelope '
             f'{"on" if campaign.envelope else "off"}; paired against {campaign.baseline} '
             '(full report: [docs/results/campaign.md](docs/results/campaign.md)).', '']
    margins = _margins_frame(law_columns)
    for key in campaign.scenarios:
        sub = rows[rows['scenario'] == key]
        if sub.empty:
            continue
        lines += [*_summary_head(sub, key), *_pairs_warning(sub, key),
                  *_summary_table(campaign, sub, key, margins), '']
    return '\n'.join(lines).strip()


def _summary_head(sub, key: str) -> list[str]:
    """The best of a scenario, and how many cannot be told apart from it (the report names
    them: the README keeps to its size)."""
    ranked = cs.ranking(sub, key, RANK_METRIC)
    tied = sum(not apart for _, _, apart in ranked[1:])
    return [f'**{scenario_name(key)}**: lowest mean RMS speed error **{ranked[0][0]}**'
            + (f'; {tied} other(s) not told apart from it at {cs.CONFIDENCE:.0%} (the report '
               'names them)' if tied else f'; told apart from every other at '
               f'{cs.CONFIDENCE:.0%}') + '.', '']


def _summary_table(campaign: Campaign, sub, key: str, margins) -> list[str]:
    """The README's table of one scenario (see summary_markdown)."""
    baseline = campaign.baseline
    means = cs.summary(sub, RANK_METRIC).set_index('law')['mean']
    diffs = cs.paired_differences(sub, baseline, RANK_METRIC).set_index('law')
    rates = cs.failure_rates(sub).set_index(['law', 'kind'])
    if not margins.empty and 'scenario' in margins.columns:
        margins = margins[margins['scenario'] == key]
    cells = {r['law']: margins_cell(r) for r in margins.to_dict('records')} \
        if not margins.empty else {}
    lines = [f'| law | mean RMS speed error, km/h (x {baseline}) | minus {baseline} '
             f'[{cs.CONFIDENCE:.0%} CI] | ATP | stop off: true / by the odometer | not ok | '
             'margins: phase, delay; at the largest actuator |', '|---|---|---|---|---|---|---|']
    base = means.get(baseline, math.nan)
    for law in [e.label for e in campaign.laws if e.label in means.index]:
        if law in diffs.index:
            d = diffs.loc[law]
            diff = f'{_f(d["mean_diff"], "+.3f")} [{_f(d["low"], "+.3f")}, ' \
                   f'{_f(d["high"], "+.3f")}]'
        else:
            diff = '(baseline)'
        counts = [f'{rates.loc[(law, kind), "k"]}/{rates.loc[(law, kind), "n"]}'
                  for kind in ('ATP intervention', cs.STOP_KIND, cs.ODOMETER_STOP_KIND,
                               'not ok')]
        ratio = means[law] / base if base else math.nan
        lines.append(f'| {law} | {_f(means[law], ".3f")} (x{_f(ratio, ".2f")}) | {diff} | '
                     f'{counts[0]} | {counts[1]} / {counts[2]} | {counts[3]} | '
                     f'{cells.get(law, "-")} |')
    return lines


def update_readme(path: Path, summary: str) -> Path:
    """Replace the text between README_START and README_END of ``path`` by ``summary``."""
    text = path.read_text()
    if README_START not in text or README_END not in text:
        raise ValueError(f'{path}: no campaign summary markers ({README_START!r} ... '
                         f'{README_END!r}) to write between')
    head, rest = text.split(README_START, 1)
    _, tail = rest.split(README_END, 1)
    path.write_text(f'{head}{README_START}\n{summary}\n{README_END}{tail}')
    return path


def write_report(campaign: Campaign, rows, folder: Path, command: str, elapsed_s: float,
                 results_page: Path | None = None, measured=None,
                 readme: Path | None = None, law_columns=None) -> Path:
    """The report, its plots and its statistics (CSV, JSON) in ``folder``; the results page
    and the README's summary if asked. ``law_columns``: extra per-law columns of the overview
    (a DataFrame indexed by law label, or with columns scenario and law); with the loop
    margins of ``margins.campaign_margins`` the report, its statistics and the summary show
    them beside the results."""
    folder.mkdir(parents=True, exist_ok=True)
    tables = statistics(campaign, rows, law_columns)
    body = markdown(campaign, rows, command, elapsed_s, tables=tables)
    path = folder / 'report.md'
    path.write_text(f'# Campaign {campaign.name}\n\n`{command}`\n\n{body}\n')
    write_statistics(campaign, tables, folder, command)
    plot(campaign, rows, folder, tables)
    if results_page is not None:
        page_body = markdown(campaign, rows, command, elapsed_s, plots=False, tables=tables)
        write_results_page(results_page, f'Campaign {campaign.name}', command,
                           page_body + f'\n\nThe plots, `stats/*.csv` and `report.json` are '
                           f'written beside `{path}` when the command runs.', measured)
    if readme is not None:
        update_readme(readme, summary_markdown(campaign, rows, command, law_columns))
    return path
