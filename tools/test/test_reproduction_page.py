"""The "paper versus suite" page is made from the claims the tests recorded."""

from ato_tools import reproduction


def test_the_page_has_a_table_per_paper_with_every_claim_and_the_failed_tests():
    claims = [
        dict(paper='luo_xu', claim='Theorem 1', paper_figure='z1 -> 0', suite_figure='1.0 cm',
             setup='flat', verdict='reproduced', reason='', test='a.py::test_one'),
        dict(paper='tan_jiang_chen', claim='jump | transient', paper_figure='smallest',
             suite_figure='largest', setup='jinan', verdict='not reproduced',
             reason='the adaptive models win', test='b.py::test_two'),
    ]
    body = reproduction.page_body(claims, ['c.py::test_three'])
    assert '## Luo & Xu: direct robust adaptive backstepping' in body
    assert '(../papers/tan_jiang_chen.md)' in body
    assert '| Theorem 1 | z1 -> 0 | 1.0 cm | flat | reproduced | `test_one` |' in body
    assert 'jump \\| transient' in body          # a cell's bar does not split the table
    assert 'not reproduced: the adaptive models win' in body
    assert '`c.py::test_three`' in body


def test_every_reproduction_test_file_exists_and_records_claims():
    for path in reproduction.REPRODUCTION_TESTS:
        source = (reproduction.REPOSITORY / path).read_text()
        assert 'record(Claim(' in source, path
