"""The report of a campaign: ``<out>/<name>/report.md`` and its PNG plots, from the rows.

Per scenario: the distribution of each metric per law (mean, median, p95, worst over the runs
with metrics: ok or diverged), the failure rates with Wilson intervals, the paired differences
against the baseline law with bootstrap intervals, the ranking by RMS speed error (saying which
laws cannot be told apart from the best), the parameters that drive each law's RMS speed error
and stop error (Spearman's rank correlation), and three plots: box plots of the metrics per
law, the empirical CDF of the stop error, and the RMS speed error against the most influential
parameter.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ato_campaigns import stats as cs
from ato_campaigns.engine import STOP_ERROR_LIMIT_M, Campaign
from ato_campaigns.provenance import write_results_page
from ato_common import uncertainty

#: the metric the ranking and the sensitivity use
RANK_METRIC = 'rms_speed_error_kmh'
TABLE_METRICS = (('rms_speed_error_kmh', 'RMS speed error (km/h)', '.3f'),
                 ('max_speed_error_kmh', 'max speed error (km/h)', '.3f'),
                 ('rms_position_error_m', 'RMS position error (m)', '.3f'),
                 ('stop_error_m', 'worst stop error (m)', '.3f'),
                 ('arrival_error_s', 'arrival-time error (s)', '.2f'),
                 ('traction_energy_kwh', 'traction energy (kWh)', '.1f'),
                 ('max_jerk_mps3', 'max jerk (m/s^3)', '.2f'),
                 ('max_acceleration_mps2', 'max acceleration (m/s^2)', '.3f'),
                 ('saturated_fraction', 'share of steps saturated', '.3f'),
                 ('atp_interventions', 'ATP interventions', '.2f'),
                 ('watchdog_events', 'watchdog periods', '.2f'))
#: the metrics whose drivers the report names
SENSITIVITY_METRICS = ('rms_speed_error_kmh', 'stop_error_m')
BOX_METRICS = ('rms_speed_error_kmh', 'stop_error_m', 'traction_energy_kwh', 'max_jerk_mps3')


def _f(value: float, fmt: str) -> str:
    return '-' if value is None or (isinstance(value, float) and math.isnan(value)) \
        else format(value, fmt)


def scenario_name(key: str) -> str:
    return Path(key).stem if key.endswith(('.yaml', '.yml')) else key


def markdown(campaign: Campaign, rows, command: str, elapsed_s: float,
             plots: bool = True) -> str:
    lines = []
    runs = len(rows)
    statuses = rows['status'].value_counts().to_dict() if runs else {}
    lines += [f'Campaign `{campaign.name}` ({campaign.origin}): {len(campaign.scenarios)} '
              f'scenario(s) x {len(campaign.laws)} laws x {campaign.draws} draws, seed '
              f'{campaign.seed}: {runs} runs ('
              + ', '.join(f'{n} {s}' for s, n in sorted(statuses.items())) +
              f'); the runs took {rows["wall_s"].sum():.0f} s in sum, this command '
              f'{elapsed_s:.0f} s of wall time on {os.cpu_count()} cores (a resumed campaign '
              'runs only the missing rows); offline closed loop, the plant perturbed by each draw, '
              'the controller on the nominal train.', '',
              '## Uncertainty', '']
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
    for key in campaign.scenarios:
        name = scenario_name(key)
        sub = rows[rows['scenario'] == key]
        if sub.empty:
            continue
        lines += [f'## {name}', '']
        ranked = cs.ranking(sub, key, RANK_METRIC)
        best = ranked[0][0]
        tied = [law for law, _, apart in ranked[1:] if not apart]
        order = ' < '.join(f'{law} ({mean:.3f})' for law, mean, _ in ranked)
        lines += [f'Ranking by mean RMS speed error over the runs with metrics (km/h): {order}. '
                  f'Best: **{best}**' + (f'; cannot be told apart from it at '
                                   f'{cs.CONFIDENCE:.0%} (paired bootstrap interval contains 0): '
                                   + ', '.join(tied) if tied else
                                   '; every other law is told apart from it at '
                                   f'{cs.CONFIDENCE:.0%}') + '.', '']
        lines += ['### Metrics (the runs with metrics, ok or diverged: mean / median / p95 / '
                  'worst)', '',
                  '| metric | ' + ' | '.join(e.label for e in campaign.laws) + ' |',
                  '|---|' + '---|' * len(campaign.laws)]
        for metric, label, fmt in TABLE_METRICS:
            table = cs.summary(sub, metric).set_index('law')
            cells = []
            for e in campaign.laws:
                if e.label not in table.index:
                    cells.append('-')
                    continue
                r = table.loc[e.label]
                cells.append(' / '.join(_f(r[c], fmt) for c in ('mean', 'median', 'p95',
                                                                 'worst')))
            lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
        lines += ['', f'### Failure rates ({cs.CONFIDENCE:.0%} Wilson intervals)', '',
                  '| law | kind | k / n | rate | interval |', '|---|---|---|---|---|']
        for r in cs.failure_rates(sub).itertuples():
            lines.append(f'| {r.law} | {r.kind} | {r.k} / {r.n} | {r.rate:.3f} | '
                         f'[{r.low:.3f}, {r.high:.3f}] |')
        lines += ['', f'### Paired differences against {campaign.baseline} (same draws; '
                  f'{cs.CONFIDENCE:.0%} bootstrap intervals of the mean)', '',
                  '| law | metric | pairs | mean difference | interval |', '|---|---|---|---|---|']
        for metric, label, fmt in TABLE_METRICS[:7]:
            for r in cs.paired_differences(sub, campaign.baseline, metric).itertuples():
                lines.append(f'| {r.law} | {label} | {r.pairs} | {_f(r.mean_diff, fmt)} | '
                             f'[{_f(r.low, fmt)}, {_f(r.high, fmt)}] |')
        for metric in SENSITIVITY_METRICS:
            label = dict((m, text) for m, text, _ in TABLE_METRICS)[metric]
            sens = cs.sensitivity(sub, metric)
            lines += ['', f'### What drives the {label.split(" (")[0]} (Spearman rank '
                      'correlation, the 3 strongest per law)', '',
                      '| law | parameter | rho | p-value |', '|---|---|---|---|']
            for e in campaign.laws:
                for r in sens[sens['law'] == e.label].head(3).itertuples():
                    lines.append(f'| {r.law} | `{r.parameter}` | {r.rho:+.2f} | '
                                 f'{r.p_value:.2g} |')
        failed = sub[sub['status'] != 'ok']
        if len(failed):
            lines += ['', '### Runs that did not finish ok', '', '| law | draw | status | reason |',
                      '|---|---|---|---|']
            for r in failed.head(20).itertuples():
                lines.append(f'| {r.law} | {r.draw} | {r.status} | '
                             f'{str(r.reason).replace("|", "/")} |')
        lines.append('')
        if plots:
            lines += [f'![metrics]({name}_metrics.png)', '',
                      f'![stop error]({name}_stop_ecdf.png)', '',
                      f'![sensitivity]({name}_sensitivity.png)', '']
    return '\n'.join(lines)


def plot(campaign: Campaign, rows, folder: Path) -> list[Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    paths = []
    labels = [e.label for e in campaign.laws]
    for key in campaign.scenarios:
        name = scenario_name(key)
        ok = rows[(rows['scenario'] == key) & rows['status'].isin(cs.MEASURED)]
        if ok.empty:
            continue
        fig, axes = plt.subplots(1, len(BOX_METRICS), figsize=(4 * len(BOX_METRICS), 4))
        for ax, metric in zip(axes, BOX_METRICS):
            data = [ok[ok['law'] == law][metric].dropna().to_numpy() for law in labels]
            ax.boxplot(data, showmeans=True)
            ax.set_xticks(range(1, len(labels) + 1), labels, rotation=30, ha='right',
                          fontsize=8)
            label = dict((m, text) for m, text, _ in TABLE_METRICS)[metric]
            ax.set_title(label, fontsize=10)
        fig.suptitle(f'{name}: {campaign.draws} draws per law')
        paths.append(_save(fig, folder / f'{name}_metrics.png', plt))

        fig, ax = plt.subplots(figsize=(7, 4))
        for law in labels:
            e = np.sort(ok[ok['law'] == law]['stop_error_m'].dropna().to_numpy())
            if e.size:
                ax.step(e, np.arange(1, e.size + 1) / e.size, where='post', label=law)
        ax.axvline(STOP_ERROR_LIMIT_M, color='k', ls='--', lw=1,
                   label=f'+/-{STOP_ERROR_LIMIT_M:g} m')
        ax.set(xscale='log', xlabel='worst |stop error| of the run (m)',
               ylabel='share of runs', title=f'{name}: empirical CDF of the stop error')
        ax.legend(fontsize=8)
        paths.append(_save(fig, folder / f'{name}_stop_ecdf.png', plt))

        sens = cs.sensitivity(ok, RANK_METRIC)
        fig, axes = plt.subplots(1, len(labels), figsize=(3.6 * len(labels), 3.4),
                                 squeeze=False)
        for ax, law in zip(axes[0], labels):
            top = sens[sens['law'] == law].head(1)
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
        paths.append(_save(fig, folder / f'{name}_sensitivity.png', plt))
    return paths


def _save(fig, path: Path, plt) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


README_START = '<!-- campaign summary: written by make campaign, do not edit -->'
README_END = '<!-- end of the campaign summary -->'


def summary_markdown(campaign: Campaign, rows, command: str) -> str:
    """The short summary the README shows: per scenario, each law's mean RMS speed error, its
    paired difference against the baseline, and its failure rates, with intervals."""
    lines = [f'`{command}`: {len(campaign.laws)} laws x {campaign.draws} draws of the default '
             f'uncertainty, seed {campaign.seed} (full report: '
             '[docs/results/campaign.md](docs/results/campaign.md)).', '']
    for key in campaign.scenarios:
        sub = rows[rows['scenario'] == key]
        if sub.empty:
            continue
        ranked = cs.ranking(sub, key, RANK_METRIC)
        means = {law: mean for law, mean, _ in ranked}
        diffs = cs.paired_differences(sub, campaign.baseline, RANK_METRIC).set_index('law')
        rates = cs.failure_rates(sub).set_index(['law', 'kind'])
        stop = f'stop outside +/-{STOP_ERROR_LIMIT_M:g} m'
        tied = [law for law, _, apart in ranked[1:] if not apart]
        lines += [f'**{scenario_name(key)}**: lowest mean RMS speed error **{ranked[0][0]}**'
                  + (f' (not told apart at {cs.CONFIDENCE:.0%} from: {", ".join(tied)})'
                     if tied else '') + '.', '',
                  f'| law | mean RMS speed error (km/h) | minus {campaign.baseline}, '
                  f'paired [{cs.CONFIDENCE:.0%} CI] | {stop} [CI] | did not finish [CI] |',
                  '|---|---|---|---|---|']
        for law, _, _ in ranked:
            if law in diffs.index:
                d = diffs.loc[law]
                diff = f'{_f(d["mean_diff"], "+.3f")} [{_f(d["low"], "+.3f")}, ' \
                       f'{_f(d["high"], "+.3f")}]'
            else:
                diff = '(baseline)'
            cells = []
            for kind in (stop, 'did not finish'):
                r = rates.loc[(law, kind)]
                cells.append(f'{r["k"]}/{r["n"]} [{r["low"]:.2f}, {r["high"]:.2f}]')
            lines.append(f'| {law} | {_f(means[law], ".3f")} | {diff} | {cells[0]} | '
                         f'{cells[1]} |')
        lines.append('')
    return '\n'.join(lines).strip()


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
                 readme: Path | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    body = markdown(campaign, rows, command, elapsed_s)
    path = folder / 'report.md'
    path.write_text(f'# Campaign {campaign.name}\n\n`{command}`\n\n{body}\n')
    plot(campaign, rows, folder)
    if results_page is not None:
        page_body = markdown(campaign, rows, command, elapsed_s, plots=False)
        write_results_page(results_page, f'Campaign {campaign.name}', command,
                           page_body + f'\n\nThe plots are written beside `{path}` when the '
                           'command runs.', measured)
    if readme is not None:
        update_readme(readme, summary_markdown(campaign, rows, command))
    return path
