"""Every law with a paper has its note in docs/papers, the note carries every equation number
the law's module cites, the index lists the law, and nothing outside README.md and docs/ points
at the external notes any more."""

from __future__ import annotations

import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

from ato_controller_node.laws import LAWS

ROOT = Path(__file__).resolve().parents[2]
NOTES = ROOT / 'docs' / 'papers'
EXTERNAL_NOTES = 'shared' + '/papers'   # split, so that this file does not cite it itself

# How the modules cite equations: "eq 8", "eq (20)", "eqs 7-8" ...
_EQ_WORD = re.compile(r'\beqs?\.?[ \t]*\(?(\d{1,2})\)?(?:[ \t]*(-)[ \t]*\(?(\d{1,2})\)?)?')
# ... and a parenthesised number, alone or paired: "(25)", "of (64)", "(15)-(16)" (a range),
# "(24)/(26)" (both). Not a call or an index ("x(0)", "sqrt(3)": a word character or "(" just
# before) and not Tan et al.'s numbered comparison methods ("comparison method (2)").
_PARENTHESISED = re.compile(
    r'(?<![\w(])(?<!method )\((\d{1,2})\)(?:[ \t]*([-/])[ \t]*\((\d{1,2})\))?')


def cited_equations(text: str) -> dict[int, list[str]]:
    """Equation number -> the citations of it in ``text`` (a range cites every number in it)."""
    found: dict[int, list[str]] = {}
    for pattern in (_EQ_WORD, _PARENTHESISED):
        for match in pattern.finditer(text):
            first, separator, last = match.groups()
            numbers = [int(first)]
            if last is not None:
                low, high = int(first), int(last)
                if separator == '-' and 0 < high - low <= 30:
                    numbers = list(range(low, high + 1))
                else:
                    numbers = [low, high]
            for number in numbers:
                found.setdefault(number, []).append(match.group(0))
    return found


def laws_with_papers():
    return [law for law in LAWS.values() if law.paper is not None]


def _note(law) -> Path:
    return NOTES / f'{law.paper}.md'


def test_the_citation_pattern_matches_the_forms_the_modules_use():
    text = ('Plant (eq 3): ... eq (20), eqs 7-8, (12), of (64), (15)-(16), eqs (16)/(24) and '
            '(24)/(26); not x(0), sqrt(3), range(4), (paper: 2), comparison method (2)')
    assert sorted(cited_equations(text)) == [3, 7, 8, 12, 15, 16, 20, 24, 26, 64]


def test_every_law_declares_its_paper_and_the_note_exists():
    undeclared = [name for name, law in LAWS.items() if 'paper' not in vars(law)]
    assert not undeclared, f'laws that do not set ControlLaw.paper themselves: {undeclared}'
    assert LAWS['pid'].paper is None  # the baseline is the suite's own
    missing = {law.name: str(_note(law).relative_to(ROOT)) for law in laws_with_papers()
               if not _note(law).is_file()}
    assert not missing, f'laws whose note is missing: {missing}'


@pytest.mark.parametrize('name', sorted(law.name for law in laws_with_papers()))
def test_every_equation_the_module_cites_is_in_the_note(name):
    law = LAWS[name]
    module = sys.modules[law.__module__]
    cited = cited_equations(inspect.getsource(module))
    assert cited, f'{module.__name__} cites no equation: is the pattern still right?'
    in_note = cited_equations(_note(law).read_text())
    missing = sorted(set(cited) - set(in_note))
    assert not missing, (
        f'{module.__name__} cites equations {missing} that {_note(law).relative_to(ROOT)} does '
        f'not give; found in the module: '
        + '; '.join(f'{n}: {sorted(set(cited[n]))}' for n in missing)
        + f'; found in the note: {sorted(in_note)}')


def test_the_index_lists_every_law_with_its_note():
    index = (NOTES / 'index.md').read_text()
    unlisted = [law.name for law in laws_with_papers() if f'`{law.name}`' not in index]
    assert not unlisted, f'laws not listed in docs/papers/index.md: {unlisted}'
    unlinked = sorted({law.paper for law in laws_with_papers()
                       if f']({law.paper}.md)' not in index})
    assert not unlinked, f'notes docs/papers/index.md does not link: {unlinked}'


def test_no_tracked_file_outside_readme_and_docs_cites_the_external_notes():
    try:
        listed = subprocess.run(['git', 'ls-files', '-z'], cwd=ROOT, check=True,
                                capture_output=True).stdout.decode()
    except (OSError, subprocess.CalledProcessError) as error:
        pytest.skip(f'not a git work tree: {error}')
    citing = []
    for name in filter(None, listed.split('\0')):
        if name == 'README.md' or name.startswith('docs/'):
            continue
        path = ROOT / name
        try:
            text = path.read_text(encoding='utf-8')
        except (OSError, UnicodeDecodeError):
            continue   # binary (or not checked out): nothing to cite
        citing += [f'{name}:{number}' for number, line in enumerate(text.splitlines(), 1)
                   if EXTERNAL_NOTES in line]
    assert not citing, f'cite docs/papers/<paper>.md instead: {citing}'
