"""No stale list of laws: every line of the repository that names several laws names every
registered one. Package descriptions, the launch file's argument, error-message examples and
the docs either name no list of laws, are generated from the registry, or list them all, so a
law added to the registry without every such list changing fails here."""

import re
import subprocess
from pathlib import Path

from ato_bringup import reference_pages
from ato_controller_node.laws import LAWS

ROOT = Path(__file__).resolve().parents[2]
#: a line naming this many distinct laws is a list of laws and must name them all
LIST_SIZE = 3


def _names_in(line: str, names) -> set[str]:
    return {n for n in names if re.search(rf'(?<![A-Za-z0-9_]){re.escape(n)}(?![A-Za-z0-9_])',
                                          line)}


def incomplete_lists(lines, names, where: str) -> list[str]:
    """The lines of ``lines`` that name at least LIST_SIZE of ``names`` but not all of them."""
    found = []
    for number, line in enumerate(lines, 1):
        named = _names_in(line, names)
        if len(named) >= LIST_SIZE and named != set(names):
            missing = ', '.join(sorted(set(names) - named))
            found.append(f'{where}:{number}: names {len(named)} laws, missing {missing}')
    return found


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
        stale += incomplete_lists(lines, LAWS, str(path.relative_to(ROOT)))
    assert not stale, 'lists of laws that miss a registered law:\n' + '\n'.join(stale)


def test_every_generated_page_names_every_law_where_it_lists_them():
    stale = []
    for path, page in reference_pages.PAGES.items():
        stale += incomplete_lists(page().splitlines(), LAWS, path)
    assert not stale, '\n'.join(stale)
    assert _names_in(reference_pages.laws_page(), LAWS) == set(LAWS)


def test_the_check_finds_a_list_that_misses_a_law():
    names = ('alpha', 'beta', 'gamma', 'delta')
    lines = ['valid: alpha, beta, gamma, delta', 'one law: alpha', 'alpha, beta, gamma',
             'alpha_beta gamma']
    assert incomplete_lists(lines, names, 'f') == ['f:3: names 3 laws, missing delta']


def test_the_launch_file_offers_every_law():
    launch = (ROOT / 'ato_bringup/launch/ato.launch.py').read_text()
    assert 'choices=sorted(LAWS)' in launch
    assert 'from ato_controller_node.laws import LAWS' in launch
