"""make reproduce: run the papers' reproduction tests and write the "paper versus suite" page.

    python -m ato_tools.reproduction [--results-page docs/results/reproduction.md]

Runs the reproduction tests (:data:`REPRODUCTION_TESTS`) with ``ato_common.evidence``'s log
switched on, then writes one table per paper: each claim, the paper's figure, the figure the
test measured in this run, the set-up, and whether it reproduces (with the reason where it does
not). A test that fails records nothing: the page lists it as failed, and the command exits
with pytest's code.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ElementTree
from pathlib import Path

from ato_campaigns.provenance import REPOSITORY, results_page_provenance, write_results_page
from ato_common.evidence import (
    COMPARABLE_FACTOR,
    LOG_VARIABLE,
    NOT_COMPARABLE,
    SUITE_EXTENSION,
    read_claims,
)

#: the test files that record claims, relative to the repository
REPRODUCTION_TESTS = (
    'ato_simulation/test/test_luo_xu_theorems_closed_loop.py',
    'ato_controller_node/test/test_mao_2017.py',
    'ato_simulation/test/test_mao_2017_suite_plant.py',
    'ato_simulation/test/test_tan_reproduction.py',
    'ato_simulation/test/test_mao_multibody_reproduction.py',
    'ato_simulation/test/test_liu_li_reproduction.py',
)
DEFAULT_RESULTS_PAGE = Path('docs/results/reproduction.md')


def _cell(text: str) -> str:
    return str(text).replace('|', '\\|').replace('\n', ' ')


def _paper_title(stem: str) -> str:
    note = REPOSITORY / 'docs' / 'papers' / f'{stem}.md'
    if note.exists():
        for line in note.read_text().splitlines():
            if line.startswith('# '):
                return line[2:].strip()
    return stem


def page_body(claims: list[dict], failed: list[str]) -> str:
    lines = ['Each row is a claim of a paper as a reproduction test tried it in this run: the '
             "paper's figure, the figure the test measured, the set-up, and the verdict. The "
             'papers are summarised in the [paper notes](../papers/index.md); how each law was '
             'implemented is in [Control laws](../guide/laws.md).', '',
             f'Verdicts: reproduced, partly reproduced or not reproduced for a claim of the '
             f'paper; *{SUITE_EXTENSION}* for a row that tests what the suite adds (an option '
             'of its own, actuator limits the paper does not have, a continuous-time design '
             'sampled at an onboard rate), which neither confirms nor refutes the paper; '
             f'*{NOT_COMPARABLE}* where the suite\'s figures differ from the paper\'s by more '
             f'than {COMPARABLE_FACTOR:g}x (the set-ups differ too much for a verdict).', '']
    if failed:
        lines += ['**Tests that failed in this run (they recorded nothing):** '
                  + ', '.join(f'`{t}`' for t in failed), '']
    papers = []
    for claim in claims:
        if claim['paper'] not in papers:
            papers.append(claim['paper'])
    for paper in papers:
        lines += [f'## {_paper_title(paper)}', '',
                  f'Notes: [{paper}](../papers/{paper}.md).', '',
                  '| claim | paper | suite | set-up | verdict | test |',
                  '|---|---|---|---|---|---|']
        for c in (c for c in claims if c['paper'] == paper):
            verdict = c['verdict'] + (f': {c["reason"]}' if c.get('reason') else '')
            test = c.get('test', '').split('::')[-1]
            lines.append(f'| {_cell(c["claim"])} | {_cell(c["paper_figure"])} | '
                         f'{_cell(c["suite_figure"])} | {_cell(c["setup"])} | '
                         f'{_cell(verdict)} | `{test}` |')
        lines.append('')
    return '\n'.join(lines)


def _failed_tests(junit: Path) -> list[str]:
    if not junit.exists():
        return ['(pytest wrote no report)']
    failed = []
    for case in ElementTree.parse(junit).iter('testcase'):
        if case.find('failure') is not None or case.find('error') is not None:
            failed.append(f'{case.get("classname", "")}::{case.get("name", "")}')
    return failed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--results-page', type=Path, default=DEFAULT_RESULTS_PAGE)
    parser.add_argument('pytest_args', nargs='*', help='further arguments to pytest')
    args = parser.parse_args(argv)
    measured = results_page_provenance(args.results_page)
    with tempfile.TemporaryDirectory() as scratch:
        log, junit = Path(scratch) / 'claims.jsonl', Path(scratch) / 'junit.xml'
        env = dict(os.environ, **{LOG_VARIABLE: str(log)})
        done = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                               f'--junitxml={junit}', *REPRODUCTION_TESTS, *args.pytest_args],
                              cwd=REPOSITORY, env=env, check=False)
        claims, failed = read_claims(log), _failed_tests(junit)
    command = 'make reproduce' if argv in (None, []) else \
        ' '.join(['python -m ato_tools.reproduction', *(argv or [])])
    written = write_results_page(args.results_page, 'Reproduction of the papers', command,
                                 page_body(claims, failed), measured)
    print(f'wrote {written}: {len(claims)} claims, {len(failed)} failed tests', file=sys.stderr)
    return done.returncode


if __name__ == '__main__':
    raise SystemExit(main())
