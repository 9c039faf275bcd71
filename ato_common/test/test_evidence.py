"""The claims a reproduction test records: validated, written only when asked, read back."""

import json

import pytest

from ato_common.evidence import LOG_VARIABLE, Claim, read_claims, record


def claim(**changes):
    values = dict(paper='luo_xu', claim='Theorem 1', paper_figure='z1 -> 0',
                  suite_figure='1.0 cm', setup='luo_xu_crh3, 10 Hz', verdict='reproduced')
    values.update(changes)
    return Claim(**values)


def test_a_claim_needs_a_known_verdict_its_figures_and_a_reason_when_not_reproduced():
    with pytest.raises(ValueError, match="verdict 'fine' is not one of"):
        claim(verdict='fine')
    with pytest.raises(ValueError, match='needs a suite_figure'):
        claim(suite_figure=' ')
    with pytest.raises(ValueError, match='not reproduced needs its reason'):
        claim(verdict='not reproduced')
    assert claim(verdict='partly reproduced', reason='a residual').reason == 'a residual'


def test_record_writes_nothing_without_the_variable(tmp_path, monkeypatch):
    monkeypatch.delenv(LOG_VARIABLE, raising=False)
    monkeypatch.chdir(tmp_path)
    assert record(claim()) == claim()
    assert list(tmp_path.iterdir()) == []


def test_record_appends_and_read_claims_gives_them_back_with_the_test(tmp_path, monkeypatch):
    log = tmp_path / 'claims.jsonl'
    monkeypatch.setenv(LOG_VARIABLE, str(log))
    record(claim())
    record(claim(claim='Theorem 2', verdict='not reproduced', reason='drift'))
    claims = read_claims(log)
    assert [c['claim'] for c in claims] == ['Theorem 1', 'Theorem 2']
    assert claims[0]['test'].endswith('test_record_appends_and_read_claims_gives_them_back_'
                                      'with_the_test')
    assert read_claims(tmp_path / 'absent.jsonl') == []


def test_a_damaged_log_is_an_error_naming_the_line(tmp_path):
    log = tmp_path / 'claims.jsonl'
    log.write_text(json.dumps(dict(claim().__dict__)) + '\n{"paper": "x"}\n')
    with pytest.raises(ValueError, match=r'claims.jsonl:2: not a recorded claim'):
        read_claims(log)


def test_a_suite_extension_and_a_row_not_comparable_are_verdicts_with_a_reason():
    from ato_common.evidence import NOT_COMPARABLE, SUITE_EXTENSION
    assert SUITE_EXTENSION == "suite extension, outside the paper's claims"
    with pytest.raises(ValueError, match='needs its reason'):
        claim(verdict=SUITE_EXTENSION)
    assert claim(verdict=NOT_COMPARABLE, reason='56x').verdict == 'not comparable'


def test_figures_more_than_ten_times_apart_are_not_comparable():
    from ato_common.evidence import incomparable
    paper = {'s - s_hat': 5.31e-05, 'v - v_d': 0.0366, 'energy': 1.0}
    suite = {'s - s_hat': 1.47e-04, 'v - v_d': 6.53e-04, 'energy': -1.0, 'other': 5.0}
    far = incomparable(paper, suite)
    assert set(far) == {'v - v_d', 'energy'}
    assert far['v - v_d'] == pytest.approx(6.53e-04 / 0.0366)
    assert far['energy'] == float('inf')   # a sign change
    assert incomparable({'x': 1.0}, {'x': 9.9}) == {}
    assert incomparable({'x': 1.0}, {'x': 0.11}) == {}
