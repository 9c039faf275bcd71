"""No stale list of laws. A paragraph of prose, or a line of code or data, that names at least
half of the registered laws is a list of the laws and must name every one (or every law that
comes from a paper, for a list of the papers' laws). Package descriptions, the launch file's
argument, error-message examples and the docs either name no such list, generate it from the
registry, or list them all, so a law added to the registry without every such list changing
fails here."""

import math
import re
import subprocess
from pathlib import Path

from ato_controller_node.laws import LAWS
from ato_tools import reference_pages

ROOT = Path(__file__).resolve().parents[2]
#: the files read as prose, paragraph by paragraph (a list there may wrap over lines)
PROSE = ('.md', '.txt', '.xml')


def _names_in(text: str, names) -> set[str]:
    return {n for n in names if re.search(rf'(?<![A-Za-z0-9_/]){re.escape(n)}(?![A-Za-z0-9_])',
                                          text)}


def units_of(lines, prose: bool) -> list[tuple[int, str]]:
    """(first line number, text) of each unit: for prose a paragraph (lines up to a blank one,
    a table row on its own), else a line."""
    if not prose:
        return list(enumerate(lines, 1))
    units, start, current = [], 0, []
    for number, line in enumerate(list(lines) + [''], 1):
        if line.lstrip().startswith('|'):
            if current:
                units.append((start, ' '.join(current)))
                current = []
            units.append((number, line))
        elif line.strip():
            if not current:
                start = number
            current.append(line)
        elif current:
            units.append((start, ' '.join(current)))
            current = []
    return units


def incomplete_lists(lines, names, where: str, complete_sets=(), prose: bool = True) -> list[str]:
    """The units of ``lines`` that name at least half of ``names`` but not all of them nor one
    of ``complete_sets``."""
    found = []
    complete = [set(names)] + [set(c) for c in complete_sets]
    for number, text in units_of(lines, prose):
        named = _names_in(text, names)
        if len(named) < math.ceil(len(names) / 2) or named in complete:
            continue
        missing = ', '.join(sorted(set(names) - named))
        found.append(f'{where}:{number}: names {len(named)} laws, missing {missing}')
    return found


def complete_sets() -> list[set[str]]:
    """Besides all the laws: all the laws that come from a paper."""
    return [{name for name, law in LAWS.items() if law.paper}]


def _checked_files() -> list[Path]:
    """Every tracked text file except the tests (which pick laws on purpose) and data."""
    listed = subprocess.run(['git', '-C', str(ROOT), 'ls-files'], capture_output=True,
                            text=True, check=True).stdout.split()
    files = []
    for name in listed:
        path = ROOT / name
        if ('/test/' in f'/{name}' or name.startswith('tests/') or not path.is_file()
                or path.suffix not in ('.py', '.md', '.xml', '.yaml', '.yml', '.txt', '.cfg',
                                       '.toml', '.sh', '')):
            continue
        files.append(path)
    return files


def test_every_list_of_laws_in_the_repository_names_every_law():
    stale = []
    for path in _checked_files():
        try:
            lines = path.read_text().splitlines()
        except UnicodeDecodeError:
            continue
        stale += incomplete_lists(lines, LAWS, str(path.relative_to(ROOT)), complete_sets(),
                                  prose=path.suffix in PROSE)
    assert not stale, 'lists of laws that miss a registered law:\n' + '\n'.join(stale)


def test_every_generated_page_names_every_law_where_it_lists_them():
    stale = []
    for path, page in reference_pages.PAGES.items():
        stale += incomplete_lists(page().splitlines(), LAWS, path, complete_sets())
    assert not stale, '\n'.join(stale)
    assert _names_in(reference_pages.laws_page(), LAWS) == set(LAWS)


def test_the_check_finds_a_list_that_misses_a_law():
    names = ('alpha', 'beta', 'gamma', 'delta')
    lines = ['valid: alpha, beta, gamma, delta', '', 'one law: alpha', '', 'alpha, gamma', '',
             'alpha_beta gamma']
    assert incomplete_lists(lines, names, 'f') == ['f:5: names 2 laws, missing beta, delta']
    # a list may wrap over lines in prose; a table row stands alone; code is read by line
    lines = ['laws: alpha,', 'gamma.', '| alpha | x |', '| gamma | x |']
    assert incomplete_lists(lines, names, 'f') == ['f:1: names 2 laws, missing beta, delta']
    assert incomplete_lists(lines, names, 'f', prose=False) == []
    # a complete set other than all the names (the laws of the papers)
    assert incomplete_lists(['beta, gamma, delta'], names, 'f', [{'beta', 'gamma', 'delta'}]) \
        == []


def test_the_launch_file_offers_every_law():
    from ato_bringup.launch_arguments import arguments
    launch = (ROOT / 'ato_bringup/launch/ato.launch.py').read_text()
    # its arguments are those of launch_arguments (which ato launch reads too)
    assert 'from ato_bringup.launch_arguments import' in launch and 'arguments()' in launch
    (controller,) = [a for a in arguments() if a.name == 'controller']
    assert controller.choices == tuple(sorted(LAWS))
