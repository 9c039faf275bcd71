"""pytest imports the test files of every package folder (pytest.ini's testpaths) as top-level
modules of their base names: two test files of one name make the second an import error."""

from collections import defaultdict

from ato_tools.house import REPOSITORY


def test_no_two_test_files_share_a_name():
    folders = [REPOSITORY / line for line in (REPOSITORY / 'pytest.ini').read_text().split(
        'testpaths =', 1)[1].splitlines()[0].split()]
    found = defaultdict(list)
    for folder in folders:
        for path in folder.rglob('test_*.py'):
            found[path.name].append(str(path.relative_to(REPOSITORY)))
    assert not {name: paths for name, paths in found.items() if len(paths) > 1}
