"""`make test` lints the repository and builds the documentation strictly; both must fail on a
broken input, not only pass on a good one. These tests break a copy and watch them fail."""

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(*command, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=300,
                          check=False)


def test_the_linter_fails_on_an_unused_import_and_on_a_long_line(tmp_path):
    shutil.copy(ROOT / 'ruff.toml', tmp_path / 'ruff.toml')
    (tmp_path / 'good.py').write_text('import math\n\nprint(math.pi)\n')
    assert _run(sys.executable, '-m', 'ruff', 'check', '.', cwd=tmp_path).returncode == 0
    (tmp_path / 'bad.py').write_text('import os\n\nx = "' + 'a' * 100 + '"\n')
    done = _run(sys.executable, '-m', 'ruff', 'check', '.', cwd=tmp_path)
    assert done.returncode == 1
    assert 'F401' in done.stdout and 'E501' in done.stdout


def test_the_type_checker_fails_on_a_wrong_type_in_a_listed_package(tmp_path):
    """mypy, with the repository's mypy.ini, over a package of the list: clean, then with a
    string passed for a float."""
    config = (ROOT / 'mypy.ini').read_text()
    package = tmp_path / 'ato_ros' / 'ato_ros'
    package.mkdir(parents=True)
    (package / '__init__.py').write_text('')
    (package / 'sample.py').write_text('def twice(x: float) -> float:\n    return 2 * x\n')
    (tmp_path / 'mypy.ini').write_text(config)
    command = (sys.executable, '-m', 'mypy', '--cache-dir', str(tmp_path / 'cache'),
               '-p', 'ato_ros')
    assert _run(*command, cwd=tmp_path).returncode == 0
    (package / 'use.py').write_text('from ato_ros.sample import twice\n\ntwice("1")\n')
    done = _run(*command, cwd=tmp_path)
    assert done.returncode == 1 and 'arg-type' in done.stdout


def test_mypy_checks_every_package_it_lists_and_make_lint_runs_it():
    config = (ROOT / 'mypy.ini').read_text()
    listed = next(line for line in config.splitlines() if line.startswith('packages ='))
    for name in listed.split('=', 1)[1].split(','):
        folder = 'tools' if name.strip() == 'ato_tools' else name.strip()
        assert (ROOT / folder / name.strip() / '__init__.py').exists(), name
    lint = (ROOT / 'Makefile').read_text().split('\nlint:', 1)[1].split('\n\n', 1)[0]
    assert 'mypy' in lint


def test_mypy_lists_every_package_of_the_suite():
    """The list is the whole product: each ament package, and the house's tools."""
    config = (ROOT / 'mypy.ini').read_text()
    listed = next(line for line in config.splitlines() if line.startswith('packages ='))
    names = {name.strip() for name in listed.split('=', 1)[1].split(',')}
    packages = {manifest.parent.name for manifest in ROOT.glob('*/package.xml')}
    assert packages and packages | {'ato_tools'} <= names, sorted(packages - names)


def _site_copy(tmp_path) -> Path:
    site = tmp_path / 'site-source'
    shutil.copytree(ROOT / 'docs', site / 'docs')
    shutil.copy(ROOT / 'mkdocs.yml', site / 'mkdocs.yml')
    (site / 'scripts').mkdir()
    shutil.copy(ROOT / 'scripts/gen_reference_docs.py', site / 'scripts')
    return site


def _build(site) -> subprocess.CompletedProcess:
    return _run(sys.executable, '-m', 'mkdocs', 'build', '--strict', '--site-dir',
                str(site / 'out'), cwd=site)


def test_the_docs_build_fails_on_a_broken_link_and_on_a_page_left_out(tmp_path):
    site = _site_copy(tmp_path)
    index = site / 'docs/index.md'
    index.write_text(index.read_text() + '\nSee [the missing page](guide/no_such_page.md).\n')
    done = _build(site)
    assert done.returncode != 0
    assert 'no_such_page.md' in done.stdout + done.stderr

    site = _site_copy(tmp_path / 'second')
    (site / 'docs/orphan.md').write_text('# A page no navigation names\n')
    done = _build(site)
    assert done.returncode != 0
    assert 'orphan.md' in done.stdout + done.stderr


def test_the_docs_build_fails_on_a_missing_anchor(tmp_path):
    site = _site_copy(tmp_path)
    index = site / 'docs/index.md'
    index.write_text(index.read_text() + '\nSee [a law](reference/laws.md#no_such_law).\n')
    done = _build(site)
    assert done.returncode != 0
    assert 'no_such_law' in done.stdout + done.stderr


def test_the_root_license_is_the_one_every_package_declares():
    """LICENSE is the Apache License 2.0 text, and every package.xml and setup.py says so."""
    import xml.etree.ElementTree as ElementTree

    from ato_tools.house import PACKAGES
    text = (ROOT / 'LICENSE').read_text()
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text
    assert 'END OF TERMS AND CONDITIONS' in text
    for package in PACKAGES:
        declared = ElementTree.parse(ROOT / package / 'package.xml').getroot().findtext('license')
        assert declared == 'Apache-2.0', f'{package}/package.xml: license {declared!r}'
        assert "license='Apache-2.0'" in (ROOT / package / 'setup.py').read_text(), package
