"""The campaign report's statistics (ato_campaigns.stats) against values computed by hand or
published: the paired failure comparison (Newcombe's interval, McNemar's exact test), the
differences of medians and of 95th percentiles, exact Spearman p-values, signed stop errors,
the Pareto view and the convergence with the number of draws."""

from __future__ import annotations

import json
import math
from itertools import permutations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from ato_campaigns import stats as cs


def test_newcombe_s_paired_interval_matches_published_values():
    # Fagerland, Lydersen & Laake, Statistical Analysis of Contingency Tables (2017), ch. 8:
    # complete response before and after consolidation therapy (Cavo et al. 2012), the table
    # [[59, 6], [16, 80]]: -0.0621 (95 % CI -0.1186 to -0.0046)
    difference, low, high = cs.newcombe_paired(59, 6, 16, 80)
    assert (round(difference, 4), round(low, 4), round(high, 4)) == (-0.0621, -0.1186, -0.0046)
    # and the table [[1, 0], [0, 1]]: 0 (-0.5734 to 0.5734)
    assert [round(v, 4) for v in cs.newcombe_paired(1, 0, 0, 1)] == [0.0, -0.5734, 0.5734]
    assert all(math.isnan(v) for v in cs.newcombe_paired(0, 0, 0, 0))


def test_mcnemar_s_exact_test_is_the_binomial_test_of_the_discordant_pairs():
    # 6 discordant pairs, all one way: 2 * 0.5^6
    assert cs.mcnemar_exact(6, 0) == pytest.approx(2 * 0.5 ** 6)
    # 1 of 7 discordant pairs: 2 * (1 + 7) / 2^7
    assert cs.mcnemar_exact(1, 6) == pytest.approx(2 * 8 / 128)
    assert cs.mcnemar_exact(0, 0) == 1.0


def failing_table() -> pd.DataFrame:
    """Laws A (the baseline) and B on 10 draws: B has an ATP intervention in draws 0-5, A in
    draw 0 only; B is late in draw 9 (arrived 30 s after the timetable)."""
    rows = []
    for draw in range(10):
        for law in ('A', 'B'):
            atp = (law == 'A' and draw == 0) or (law == 'B' and draw < 6)
            late = law == 'B' and draw == 9
            rows.append({'scenario': 's', 'law': law, 'draw': draw,
                         'status': 'ATP intervention' if atp else 'late' if late else 'ok',
                         'atp_interventions': 2.0 if atp else 0.0,
                         'arrival_delay_s': 30.0 if late else 1.0, 'stop_error_m': 0.2,
                         'rms_speed_error_kmh': 1.0})
    return pd.DataFrame(rows)


def test_the_paired_failures_count_the_discordant_draws():
    table = cs.paired_failures(failing_table(), 'A').set_index(['law', 'kind'])
    atp = table.loc[('B', 'ATP intervention')]
    # both in draw 0, B only in draws 1-5, A only never, neither in draws 6-9
    assert [atp[c] for c in ('pairs', 'both', 'law_only', 'baseline_only', 'neither')] == \
        [10, 1, 5, 0, 4]
    assert atp['rate_diff'] == pytest.approx(0.5)
    assert atp['mcnemar_p'] == pytest.approx(2 * 0.5 ** 5)
    expected = cs.newcombe_paired(1, 5, 0, 4)
    assert [atp['rate_diff'], atp['low'], atp['high']] == pytest.approx(list(expected))
    assert atp['low'] > 0.0   # B fails more often than A, on the same draws
    late = table.loc[('B', 'late')]
    assert (late['law_only'], late['baseline_only'], late['mcnemar_p']) == (1, 0, 1.0)
    not_ok = table.loc[('B', 'not ok')]
    assert (not_ok['both'], not_ok['law_only']) == (1, 6)


def test_the_paired_differences_of_medians_and_p95_have_bootstrap_intervals():
    rows = []
    a = np.arange(1.0, 31.0)
    b = a * 2.0   # B's distribution is A's scaled by 2
    for draw in range(30):
        for law, value in (('A', a[draw]), ('B', b[draw])):
            rows.append({'scenario': 's', 'law': law, 'draw': draw, 'status': 'ok',
                         'rms_speed_error_kmh': value})
    r = cs.paired_differences(pd.DataFrame(rows), 'A', 'rms_speed_error_kmh').iloc[0]
    assert r['pairs'] == 30
    assert r['mean_diff'] == pytest.approx(np.mean(b - a))
    assert r['median_diff'] == pytest.approx(np.median(b) - np.median(a))
    assert r['p95_diff'] == pytest.approx(np.percentile(b, 95) - np.percentile(a, 95))
    for stat in ('median', 'p95'):
        assert r[f'{stat}_low'] < r[f'{stat}_diff'] < r[f'{stat}_high']
    # the pairs are resampled together: B - A = A, so the median difference's interval is
    # that of A's median, within A's range
    assert 1.0 <= r['median_low'] and r['median_high'] <= 30.0


def test_spearman_s_p_value_is_exact_at_small_n():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    y = np.array([2.0, 1.0, 4.0, 3.0, 6.0, 5.0])
    rho, p, method = cs.spearman(x, y)
    assert method == 'exact' and rho == pytest.approx(stats.spearmanr(x, y).statistic)
    # by hand: the share of the 720 orderings of y whose |rho| is at least this one's
    ranks = np.arange(1, 7)

    def rho_of(order):
        d = ranks - np.array(order)
        return 1 - 6 * np.sum(d * d) / (6 * 35)

    null = np.array([rho_of(order) for order in permutations(ranks)])
    assert p == pytest.approx(np.mean(np.abs(null) >= abs(rho) - 1e-12))
    assert p != pytest.approx(stats.spearmanr(x, y).pvalue, rel=1e-3)   # not the t value
    many = np.arange(30.0)
    assert cs.spearman(many, many[::-1] ** 2)[2] == 't'


def test_signed_stop_errors_keep_over_and_undershoots_apart():
    rows = pd.DataFrame([
        {'scenario': 's', 'law': 'A', 'draw': d, 'status': 'ok',
         'stop_errors_m': json.dumps({'B': e, 'C': 0.1})}
        for d, e in enumerate([0.7, -0.8, -0.9, 0.2, -0.1])])
    table = cs.signed_stop_errors(rows).set_index('stop')
    b = table.loc['B']
    assert (b['n'], b['overshoots'], b['undershoots']) == (5, 1, 2)
    assert b['mean'] == pytest.approx(np.mean([0.7, -0.8, -0.9, 0.2, -0.1]))
    assert b['median'] == pytest.approx(-0.1)
    assert (table.loc['C', 'overshoots'], table.loc['C', 'undershoots']) == (0, 0)


def test_the_pareto_view_names_who_dominates_whom():
    rows = pd.DataFrame([
        {'scenario': 's', 'law': law, 'draw': 0, 'status': 'ok', 'rms_speed_error_kmh': e,
         'traction_energy_kwh': w, 'stop_error_m': x}
        for law, e, w, x in (('fast', 1.0, 90.0, 0.2), ('frugal', 2.0, 70.0, 0.2),
                             ('worse', 2.0, 95.0, 0.3), ('tie', 1.0, 90.0, 0.2))])
    table = cs.pareto(rows).set_index('law')
    assert table.loc['fast', 'dominated_by'] == '' and table.loc['frugal', 'dominated_by'] == ''
    assert table.loc['tie', 'dominated_by'] == ''   # equal in all: neither dominates
    assert table.loc['worse', 'dominated_by'] == 'fast, frugal, tie'


def test_convergence_gives_the_running_estimates_in_draw_order():
    rows = pd.DataFrame([
        {'scenario': 's', 'law': 'A', 'draw': d, 'status': s, 'rms_speed_error_kmh': v}
        for d, (s, v) in enumerate([('ok', 1.0), ('late', 3.0), ('error', math.nan),
                                    ('ok', 2.0)])])
    table = cs.convergence(rows, 'rms_speed_error_kmh')
    assert list(table['draws']) == [1, 2, 3, 4]
    assert table['mean'].tolist() == pytest.approx([1.0, 2.0, 2.0, 2.0])
    assert table['not_ok_rate'].tolist() == pytest.approx([0.0, 0.5, 2 / 3, 0.5])
    assert math.isnan(table['mean_low'].iloc[0])   # one value: no interval
    half = stats.t.ppf(0.975, 1) * np.std([1.0, 3.0], ddof=1) / math.sqrt(2)
    assert table['mean_high'].iloc[1] == pytest.approx(2.0 + half)
