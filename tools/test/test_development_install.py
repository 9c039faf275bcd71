"""An edit to the sources is what runs next: the workspace is a symlink install, so every
module of the suite is imported from its source file, and a file added to a package is
importable at once, in a fresh process, without `make setup`."""

import importlib
import os
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from ato_tools.house import PACKAGES
from ato_tools.house import REPOSITORY as ROOT


@pytest.mark.parametrize('package', PACKAGES)
def test_every_package_is_imported_from_its_source_folder(package):
    module = importlib.import_module(package)
    source = Path(os.path.realpath(module.__file__))
    assert source == ROOT / package / package / '__init__.py', (
        f'{package} is imported from {module.__file__} (-> {source}), not from the source tree: '
        'run make setup, which builds ros_ws with --symlink-install')


def test_an_edit_to_a_law_runs_in_the_next_process_without_a_rebuild():
    """A new module in the laws' folder, and then an edit of it, are what a new process
    imports, through the installed package, as `make demo` or `python -m pytest` would."""
    name = f'_edit_probe_{uuid.uuid4().hex[:8]}'
    path = ROOT / 'ato_controller_node/ato_controller_node/laws' / f'{name}.py'
    probe = [sys.executable, '-c', f'from ato_controller_node.laws import {name}; '
             f'print({name}.VALUE)']
    try:
        for value in ('first', 'edited'):
            path.write_text(f'VALUE = {value!r}\n')
            done = subprocess.run(probe, capture_output=True, text=True, timeout=60,
                                  check=False, cwd='/')
            assert done.stdout.strip() == value, done.stderr
    finally:
        path.unlink(missing_ok=True)
