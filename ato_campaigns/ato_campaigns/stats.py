"""Statistics of a campaign's rows (scipy.stats), per scenario and law.

- ``summary``: mean, median, 95th percentile and worst (largest |value|) of each metric over the
  runs that produced metrics (status ok or diverged: MEASURED);
- ``failure_rates``: the share of runs whose stop is outside +/-STOP_ERROR_LIMIT_M (a run that
  did not finish ok counts as outside; one without a stop in its window, as inside), that had
  an ATP intervention, and that did not finish (diverged, error or timeout), each with a Wilson
  score interval;
- ``paired_differences``: law minus baseline on the same draws (common random numbers, the
  draws where both produced a finite value), with a percentile bootstrap interval of the mean
  difference;
- ``ranking``: the laws by mean metric; a law whose paired interval against the best contains 0
  cannot be told apart from it at that confidence;
- ``sensitivity``: Spearman's rank correlation of each drawn parameter with a metric.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from ato_campaigns.engine import STOP_ERROR_LIMIT_M

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 12345


#: the statuses of the runs that produced metrics: a diverged run counts with its (large)
#: errors, so a law that diverges is not flattered by leaving its worst runs out
MEASURED = ('ok', 'diverged')


def _ok(rows):
    """The runs that produced metrics (MEASURED)."""
    return rows[rows['status'].isin(MEASURED)]


def summary(rows, metric: str):
    """One row per (scenario, law): n_ok, mean, median, p95, worst of ``metric``."""
    import pandas as pd
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        values = _ok(group)[metric].to_numpy(dtype=float)
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


def failure_rates(rows, confidence: float = CONFIDENCE):
    """One row per (scenario, law) and kind: k failures of n runs, rate, interval."""
    import pandas as pd
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        n = len(group)
        ok = group['status'] == 'ok'
        kinds = {
            f'stop outside +/-{STOP_ERROR_LIMIT_M:g} m':
                (~ok) | (group['stop_error_m'].abs() > STOP_ERROR_LIMIT_M),
            'ATP intervention': group['atp_interventions'].fillna(0) > 0,
            'did not finish': ~ok,
        }
        for kind, failed in kinds.items():
            k = int(failed.sum())
            low, high = wilson(k, n, confidence)
            out.append((scenario, law, kind, k, n, k / n if n else math.nan, low, high))
    return pd.DataFrame(out, columns=['scenario', 'law', 'kind', 'k', 'n', 'rate', 'low',
                                      'high'])


def bootstrap_mean(d: np.ndarray, confidence: float = CONFIDENCE,
                   seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``d`` (NaN with fewer than 2 values; the
    value itself when every value is the same)."""
    if d.size < 2:
        return math.nan, math.nan
    if np.all(d == d[0]):
        return float(d[0]), float(d[0])
    result = stats.bootstrap((d,), np.mean, confidence_level=confidence,
                             n_resamples=BOOTSTRAP_RESAMPLES, method='percentile',
                             rng=np.random.default_rng(seed))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def paired(rows, scenario: str, law: str, baseline: str, metric: str) -> np.ndarray:
    """``law`` minus ``baseline`` on the draws where both produced a finite value."""
    ok = _ok(rows[rows['scenario'] == scenario])
    a = ok[ok['law'] == law].set_index('draw')[metric]
    b = ok[ok['law'] == baseline].set_index('draw')[metric]
    d = (a - b).sort_index().to_numpy(dtype=float)
    return d[np.isfinite(d)]


def paired_differences(rows, baseline: str, metric: str, confidence: float = CONFIDENCE):
    import pandas as pd
    out = []
    for scenario in sorted(rows['scenario'].unique()):
        for law in sorted(rows[rows['scenario'] == scenario]['law'].unique()):
            if law == baseline:
                continue
            d = paired(rows, scenario, law, baseline, metric)
            low, high = bootstrap_mean(d, confidence)
            out.append((scenario, law, baseline, d.size,
                        float(np.mean(d)) if d.size else math.nan, low, high))
    return pd.DataFrame(out, columns=['scenario', 'law', 'baseline', 'pairs', 'mean_diff',
                                      'low', 'high'])


def ranking(rows, scenario: str, metric: str, confidence: float = CONFIDENCE
            ) -> list[tuple[str, float, bool]]:
    """(law, mean metric, told apart from the best) in order of the mean over the measured runs;
    a law without any comes last. The best is told apart from itself: True."""
    table = summary(rows[rows['scenario'] == scenario], metric)
    table = table.sort_values('mean', na_position='last', kind='stable')
    laws = list(table['law'])
    if not laws:
        return []
    best = laws[0]
    out = [(best, float(table['mean'].iloc[0]), True)]
    for law, mean in zip(laws[1:], table['mean'].iloc[1:]):
        low, high = bootstrap_mean(paired(rows, scenario, law, best, metric), confidence)
        apart = bool(np.isfinite(low) and low > 0.0)
        out.append((law, float(mean), apart))
    return out


def sensitivity(rows, metric: str):
    """Spearman's rho and its p-value of each drawn parameter (``p_*`` columns that vary)
    against ``metric``, per (scenario, law), over the measured runs; strongest |rho| first."""
    import pandas as pd
    params = [c for c in rows.columns if c.startswith('p_')]
    out = []
    for (scenario, law), group in rows.groupby(['scenario', 'law'], sort=True):
        ok = _ok(group)
        y = ok[metric].to_numpy(dtype=float)
        for p in params:
            x = ok[p].to_numpy(dtype=float)
            keep = np.isfinite(x) & np.isfinite(y)
            if keep.sum() < 3 or np.ptp(x[keep]) == 0.0 or np.ptp(y[keep]) == 0.0:
                continue
            rho, pvalue = stats.spearmanr(x[keep], y[keep])
            out.append((scenario, law, p[2:], float(rho), float(pvalue), int(keep.sum())))
    table = pd.DataFrame(out, columns=['scenario', 'law', 'parameter', 'rho', 'p_value', 'n'])
    if table.empty:
        return table
    return table.reindex(table['rho'].abs().sort_values(ascending=False).index).reset_index(
        drop=True)
