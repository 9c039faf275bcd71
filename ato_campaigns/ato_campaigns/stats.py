"""Statistics of a campaign's rows (scipy.stats), per scenario and law (a law is a row label of
the campaign: a law, or a law with its configuration).

- ``summary``: mean, median, 95th percentile and worst (largest |value|) of each metric over the
  runs that produced metrics (MEASURED: every status but error and timeout);
- ``failure_flags`` / ``failure_rates``: per run and kind (FAILURE_KINDS: not ok, did not
  finish, late, ATP intervention, a stop outside +/-STOP_ERROR_LIMIT_M, the same as the
  train's own odometer measured it), and the share of runs of each kind with a Wilson score
  interval;
- ``paired_failures``: each kind of failure of a law against the baseline's on the same draws:
  the discordant pairs, the paired difference of the two rates with Newcombe's hybrid score
  interval for paired proportions (Newcombe 1998, method 10) and McNemar's exact test (the
  binomial test of the discordant pairs, scipy.stats.binomtest);
- ``paired_differences``: law minus baseline on the same draws (common random numbers, the
  draws where both produced a finite value): the mean difference, and the differences of the
  medians and of the 95th percentiles, each with a paired bootstrap interval
  (scipy.stats.bootstrap, BOOTSTRAP_METHOD, BOOTSTRAP_RESAMPLES resamples);
- ``ranking``: the laws by mean metric; a law whose paired interval against the best contains 0,
  or that has fewer than MIN_PAIRS pairs with it, cannot be told apart from it;
- ``sensitivity``: Spearman's rank correlation of each drawn parameter with a metric, its
  p-value exact (every pairing, scipy.stats.permutation_test) up to SPEARMAN_EXACT_MAX_N runs;
- ``signed_stop_errors``: each stop's signed error (position minus stop: overshoot positive),
  over- and undershoot beyond the tolerance counted apart;
- ``pareto``: each law's mean RMS speed error, traction energy and worst stop error, and
  whether another law is at least as good in all three and better in one;
- ``convergence``: each law's running mean of a metric and running failure rate over the first
  1, 2, ... draws, with their intervals.
"""

from __future__ import annotations

import json
import math
from typing import Callable

import numpy as np
from scipy import stats

from ato_campaigns.engine import STOP_ERROR_LIMIT_M
from ato_common.run_events import LATE_AFTER_S, MEASURED

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_METHOD = 'percentile'
BOOTSTRAP_SEED = 12345
#: below this many pairs the report warns, and no law is told apart from another: a
#: percentile bootstrap interval is too narrow at small n (it under-covers), and an exact test
#: on fewer pairs has little power (a suite setting)
MIN_PAIRS = 20
#: up to this many runs a Spearman p-value is exact (all n! pairings); above it, scipy's
#: t approximation
SPEARMAN_EXACT_MAX_N = 8

STOP_KIND = f'stop outside +/-{STOP_ERROR_LIMIT_M:g} m'
#: a stop outside the tolerance as the train's odometer measured it: the part of STOP_KIND a law
#: can act on (the odometer's drawn error at the stop is in every law's true stop alike)
ODOMETER_STOP_KIND = f'stop outside +/-{STOP_ERROR_LIMIT_M:g} m by the odometer'
#: the kinds of failure counted per run, each on its own: a run that is late and had an ATP
#: intervention counts in both
FAILURE_KINDS = ('not ok', 'did not finish', 'late', 'ATP intervention', STOP_KIND,
                 ODOMETER_STOP_KIND)
#: the statuses of a run that did not finish (its journey, or the run itself)
UNFINISHED = ('error', 'timeout', 'diverged', 'did not finish')
#: the metrics of the Pareto view: lower is better in each
PARETO_METRICS = ('rms_speed_error_kmh', 'traction_energy_kwh', 'stop_error_m')


def _measured(rows):
    """The runs that produced metrics (MEASURED)."""
    return rows[rows['status'].isin(MEASURED)]


def _column(rows, name: str):
    import pandas as pd
    return rows[name] if name in rows.columns else pd.Series(np.nan, index=rows.index)


def summary(rows, metric: str):
    """One row per (scenario, law): n_ok, mean, median, p95, worst of ``metric``."""
    import pandas as pd
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        values = _measured(group)[metric].to_numpy(dtype=float)
        values = values[np.isfinite(values)]
        if values.size:
            out.append((scenario, law, values.size, float(np.mean(values)),
                        float(np.median(values)), float(np.percentile(values, 95)),
                        float(values[np.argmax(np.abs(values))])))
        else:
            out.append((scenario, law, 0, math.nan, math.nan, math.nan, math.nan))
    return pd.DataFrame(out, columns=['scenario', 'law', 'n_ok', 'mean', 'median', 'p95',
                                      'worst'])


def wilson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(k, n).proportion_ci(confidence, method='wilson')
    return float(ci.low), float(ci.high)


def failure_flags(rows):
    """Per run (the rows' index), whether it failed in each of FAILURE_KINDS: a run that did
    not finish counts as outside the stop tolerance, one without a stop in its window as
    inside; late is an arrival LATE_AFTER_S or more after the timetable's (of a run that
    finished)."""
    import pandas as pd
    unfinished = rows['status'].isin(UNFINISHED)
    return pd.DataFrame({
        'not ok': rows['status'] != 'ok',
        'did not finish': unfinished,
        'late': ~unfinished & (_column(rows, 'arrival_delay_s') >= LATE_AFTER_S),
        'ATP intervention': _column(rows, 'atp_interventions').fillna(0) > 0,
        STOP_KIND: unfinished | (_column(rows, 'stop_error_m').abs() > STOP_ERROR_LIMIT_M),
        ODOMETER_STOP_KIND: unfinished | (_column(rows, 'odometer_stop_error_m').abs()
                                          > STOP_ERROR_LIMIT_M),
    }, index=rows.index)


def failure_rates(rows, confidence: float = CONFIDENCE):
    """One row per (scenario, law) and kind: k failures of n runs, rate, interval."""
    import pandas as pd
    out = []
    flags = failure_flags(rows)
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        n = len(group)
        for kind in FAILURE_KINDS:
            k = int(flags.loc[group.index, kind].sum())
            low, high = wilson(k, n, confidence)
            out.append((scenario, law, kind, k, n, k / n if n else math.nan, low, high))
    return pd.DataFrame(out, columns=['scenario', 'law', 'kind', 'k', 'n', 'rate', 'low',
                                      'high'])


def newcombe_paired(a: int, b: int, c: int, d: int, confidence: float = CONFIDENCE
                    ) -> tuple[float, float, float]:
    """The difference p1 - p2 of two paired proportions and its interval by Newcombe's hybrid
    score method (Newcombe 1998, Statistics in Medicine 17, 2635-2650, method 10): ``a``
    pairs where both failed, ``b`` the first only, ``c`` the second only, ``d`` neither."""
    n = a + b + c + d
    if n == 0:
        return math.nan, math.nan, math.nan
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = wilson(a + b, n, confidence)
    l2, u2 = wilson(a + c, n, confidence)
    # the correlation of the two estimates, its numerator ad - bc corrected for continuity
    # towards 0 (by n/2 when positive, to 0 within [0, n/2]; Newcombe's phi)
    denominator = (a + b) * (c + d) * (a + c) * (b + d)
    numerator: float = a * d - b * c
    numerator = numerator - n / 2 if numerator > n / 2 else min(numerator, 0)
    phi = numerator / math.sqrt(denominator) if denominator > 0 else 0.0
    delta = math.sqrt(max((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2,
                          0.0))
    epsilon = math.sqrt(max((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2,
                            0.0))
    difference = p1 - p2
    return difference, max(difference - delta, -1.0), min(difference + epsilon, 1.0)


def mcnemar_exact(b: int, c: int) -> float:
    """McNemar's exact two-sided p-value: the binomial test of ``b`` of the ``b + c``
    discordant pairs at 1/2 (1 when there is none)."""
    return 1.0 if b + c == 0 else float(stats.binomtest(b, b + c, 0.5).pvalue)


def paired_failures(rows, baseline: str, confidence: float = CONFIDENCE):
    """Per scenario, law (not the baseline) and kind: the draws both ran (pairs), both failed
    (a), the law only (b), the baseline only (c), neither (d); the difference of the rates
    (law minus baseline) with its Newcombe interval, and McNemar's exact p-value."""
    import pandas as pd
    flags = failure_flags(rows)
    out = []
    for scenario in sorted(rows['scenario'].unique()):
        sub = rows[rows['scenario'] == scenario]
        by_law = {law: flags.loc[group.index].set_axis(group['draw'].to_numpy())
                  for law, group in sub.groupby('law')}
        if baseline not in by_law:
            continue
        base = by_law[baseline]
        for law in sorted(by_law):
            if law == baseline:
                continue
            draws = by_law[law].index.intersection(base.index)
            for kind in FAILURE_KINDS:
                x = by_law[law].loc[draws, kind].to_numpy(dtype=bool)
                y = base.loc[draws, kind].to_numpy(dtype=bool)
                a, b = int(np.sum(x & y)), int(np.sum(x & ~y))
                c, d = int(np.sum(~x & y)), int(np.sum(~x & ~y))
                diff, low, high = newcombe_paired(a, b, c, d, confidence)
                out.append((scenario, law, baseline, kind, len(draws), a, b, c, d, diff, low,
                            high, mcnemar_exact(b, c)))
    return pd.DataFrame(out, columns=['scenario', 'law', 'baseline', 'kind', 'pairs', 'both',
                                      'law_only', 'baseline_only', 'neither', 'rate_diff',
                                      'low', 'high', 'mcnemar_p'])


def _bootstrap(data: tuple[np.ndarray, ...], statistic: Callable, confidence: float,
               seed: int, paired: bool = False) -> tuple[float, float]:
    """A percentile bootstrap interval (BOOTSTRAP_METHOD) of ``statistic``; NaN with fewer
    than 2 values, the value itself when no resample can differ."""
    if data[0].size < 2:
        return math.nan, math.nan
    if all(np.all(d == d[0]) for d in data):
        value = float(statistic(*data, axis=-1))
        return value, value
    result = stats.bootstrap(data, statistic, confidence_level=confidence,
                             n_resamples=BOOTSTRAP_RESAMPLES, method=BOOTSTRAP_METHOD,
                             paired=paired, vectorized=True, rng=np.random.default_rng(seed))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def bootstrap_mean(d: np.ndarray, confidence: float = CONFIDENCE,
                   seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Bootstrap interval of the mean of ``d``."""
    return _bootstrap((d,), np.mean, confidence, seed)


def _median_difference(a, b, axis=-1):
    return np.median(a, axis=axis) - np.median(b, axis=axis)


def _p95_difference(a, b, axis=-1):
    return np.percentile(a, 95, axis=axis) - np.percentile(b, 95, axis=axis)


def paired_values(rows, scenario: str, law: str, baseline: str, metric: str
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(law's, baseline's) ``metric`` on the draws where both produced a finite value, in
    draw order."""
    ok = _measured(rows[rows['scenario'] == scenario])
    a = ok[ok['law'] == law].set_index('draw')[metric]
    b = ok[ok['law'] == baseline].set_index('draw')[metric]
    both = a.index.intersection(b.index).sort_values()
    x, y = a.loc[both].to_numpy(dtype=float), b.loc[both].to_numpy(dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    return x[keep], y[keep]


def paired(rows, scenario: str, law: str, baseline: str, metric: str) -> np.ndarray:
    """``law`` minus ``baseline`` on the draws where both produced a finite value."""
    a, b = paired_values(rows, scenario, law, baseline, metric)
    return a - b


def paired_differences(rows, baseline: str, metric: str, confidence: float = CONFIDENCE):
    """Per scenario and law: the pairs, the mean of the paired differences, the difference of
    the medians and of the 95th percentiles (law minus baseline), each with its bootstrap
    interval (the pairs resampled together)."""
    import pandas as pd
    out = []
    for scenario in sorted(rows['scenario'].unique()):
        for law in sorted(rows[rows['scenario'] == scenario]['law'].unique()):
            if law == baseline:
                continue
            a, b = paired_values(rows, scenario, law, baseline, metric)
            d = a - b
            n = d.size
            mean = float(np.mean(d)) if n else math.nan
            median = float(_median_difference(a, b)) if n else math.nan
            p95 = float(_p95_difference(a, b)) if n else math.nan
            out.append((scenario, law, baseline, n, mean, *bootstrap_mean(d, confidence),
                        median, *_bootstrap((a, b), _median_difference, confidence,
                                            BOOTSTRAP_SEED, paired=True),
                        p95, *_bootstrap((a, b), _p95_difference, confidence,
                                         BOOTSTRAP_SEED, paired=True)))
    return pd.DataFrame(out, columns=['scenario', 'law', 'baseline', 'pairs', 'mean_diff',
                                      'low', 'high', 'median_diff', 'median_low',
                                      'median_high', 'p95_diff', 'p95_low', 'p95_high'])


def ranking(rows, scenario: str, metric: str, confidence: float = CONFIDENCE
            ) -> list[tuple[str, float, bool]]:
    """(law, mean metric, told apart from the best) in order of the mean over the measured runs;
    a law without any comes last. The best is told apart from itself: True. A law with fewer
    than MIN_PAIRS pairs with the best is not told apart from it."""
    table = summary(rows[rows['scenario'] == scenario], metric)
    table = table.sort_values('mean', na_position='last', kind='stable')
    laws = list(table['law'])
    if not laws:
        return []
    best = laws[0]
    out = [(best, float(table['mean'].iloc[0]), True)]
    for law, mean in zip(laws[1:], table['mean'].iloc[1:]):
        d = paired(rows, scenario, law, best, metric)
        low, _ = bootstrap_mean(d, confidence)
        apart = bool(d.size >= MIN_PAIRS and np.isfinite(low) and low > 0.0)
        out.append((law, float(mean), apart))
    return out


def fewest_pairs(rows, scenario: str, metric: str = 'rms_speed_error_kmh') -> int:
    """The fewest draws on which two laws of ``scenario`` both produced a finite ``metric``
    (the pairs of their paired comparison; 0 with one law)."""
    laws = sorted(rows[rows['scenario'] == scenario]['law'].unique())
    counts = [paired(rows, scenario, law, other, metric).size
              for i, law in enumerate(laws) for other in laws[i + 1:]]
    return min(counts, default=0)


def spearman(x: np.ndarray, y: np.ndarray) -> tuple[float, float, str]:
    """Spearman's rho, its two-sided p-value and how it was found: 'exact' (every pairing of
    the ranks, scipy.stats.permutation_test) up to SPEARMAN_EXACT_MAX_N values, else 't'
    (scipy.stats.spearmanr's t approximation)."""
    result = stats.spearmanr(x, y)
    rho = float(result.statistic)
    if x.size > SPEARMAN_EXACT_MAX_N:
        return rho, float(result.pvalue), 't'
    rx, ry = stats.rankdata(x), stats.rankdata(y)
    rx, ry = rx - rx.mean(), ry - ry.mean()
    norm = math.sqrt(float(np.sum(rx * rx) * np.sum(ry * ry)))

    def statistic(r, axis=-1):  # rho of permuted ranks: the norm does not change
        return np.sum(r * ry, axis=axis) / norm

    exact = stats.permutation_test((rx,), statistic, permutation_type='pairings',
                                   vectorized=True, n_resamples=np.inf)
    return rho, float(min(exact.pvalue, 1.0)), 'exact'


def sensitivity(rows, metric: str):
    """Spearman's rho and its p-value (``spearman``) of each drawn parameter (``p_*`` columns
    that vary) against ``metric``, per (scenario, law), over the measured runs; strongest
    |rho| first."""
    import pandas as pd
    params = [c for c in rows.columns if c.startswith('p_')]
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        ok = _measured(group)
        y = ok[metric].to_numpy(dtype=float)
        for p in params:
            x = ok[p].to_numpy(dtype=float)
            keep = np.isfinite(x) & np.isfinite(y)
            if keep.sum() < 3 or np.ptp(x[keep]) == 0.0 or np.ptp(y[keep]) == 0.0:
                continue
            rho, pvalue, method = spearman(x[keep], y[keep])
            out.append((scenario, law, p[2:], rho, pvalue, method, int(keep.sum())))
    table = pd.DataFrame(out, columns=['scenario', 'law', 'parameter', 'rho', 'p_value',
                                       'p_method', 'n'])
    if table.empty:
        return table
    return table.reindex(table['rho'].abs().sort_values(ascending=False).index).reset_index(
        drop=True)


def signed_stop_errors(rows, tolerance_m: float = STOP_ERROR_LIMIT_M):
    """Per (scenario, law, stop): the runs that stopped there, the mean, median, 5th and 95th
    percentiles of the signed error (position minus stop: positive an overshoot), and how many
    overshot and how many undershot by more than ``tolerance_m``."""
    import pandas as pd
    out = []
    for (scenario, law), group in _measured(rows).groupby(['scenario', 'law'], sort=True):
        errors: dict[str, list[float]] = {}
        for text in group['stop_errors_m']:
            for stop, error in json.loads(text or '{}').items():
                errors.setdefault(stop, []).append(float(error))
        for stop, values in errors.items():
            e = np.array(values)
            e = e[np.isfinite(e)]
            if not e.size:
                continue
            out.append((scenario, law, stop, e.size, float(np.mean(e)), float(np.median(e)),
                        float(np.percentile(e, 5)), float(np.percentile(e, 95)),
                        int(np.sum(e > tolerance_m)), int(np.sum(e < -tolerance_m))))
    return pd.DataFrame(out, columns=['scenario', 'law', 'stop', 'n', 'mean', 'median', 'p5',
                                      'p95', 'overshoots', 'undershoots'])


def pareto(rows, metrics: tuple[str, ...] = PARETO_METRICS):
    """Per (scenario, law): the mean of each of ``metrics`` over the measured runs, and
    ``dominated_by``: the laws at least as good in every one and better in one (empty: the
    law is on the Pareto front). A metric that one of two laws lacks (no stop in a window) is
    left out of their comparison."""
    import pandas as pd
    out = []
    for scenario in sorted(rows['scenario'].unique()):
        sub = _measured(rows[rows['scenario'] == scenario])
        means = sub.groupby('law')[list(metrics)].mean()
        values = {law: row.to_numpy(dtype=float) for law, row in means.iterrows()}
        for law, mine in values.items():
            better = []
            for other, theirs in values.items():
                both = np.isfinite(mine) & np.isfinite(theirs)
                if other != law and both.any() and np.all(theirs[both] <= mine[both]) \
                        and np.any(theirs[both] < mine[both]):
                    better.append(other)
            out.append((scenario, law, *mine, ', '.join(better)))
    return pd.DataFrame(out, columns=['scenario', 'law', *metrics, 'dominated_by'])


def convergence(rows, metric: str, confidence: float = CONFIDENCE):
    """Per (scenario, law) and n = 1, 2, ... measured runs in draw order: the running mean of
    ``metric`` with its t interval, and over the first n draws the running share of runs not
    ok with its Wilson interval."""
    import pandas as pd
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        group = group.sort_values('draw')
        values = np.where(group['status'].isin(MEASURED), group[metric].to_numpy(dtype=float),
                          np.nan)
        failed = (group['status'] != 'ok').to_numpy()
        seen: list[float] = []
        for n, (value, draw) in enumerate(zip(values, group['draw']), start=1):
            if np.isfinite(value):
                seen.append(value)
            m = len(seen)
            mean = float(np.mean(seen)) if m else math.nan
            half = (float(stats.t.ppf(0.5 + confidence / 2, m - 1) * np.std(seen, ddof=1)
                          / math.sqrt(m)) if m > 1 else math.nan)
            k = int(failed[:n].sum())
            low, high = wilson(k, n, confidence)
            out.append((scenario, law, int(draw), n, mean, mean - half, mean + half,
                        k / n, low, high))
    return pd.DataFrame(out, columns=['scenario', 'law', 'draw', 'draws', 'mean', 'mean_low',
                                      'mean_high', 'not_ok_rate', 'not_ok_low', 'not_ok_high'])
