"""Integration tests over rclpy: each test starts the real executables (as ``ros2 run`` would
find them) in a DDS domain that no other test session on this machine uses at the same time,
with discovery limited to this machine, so parallel runs never hear each other.

The graph tests must hold on a loaded machine: ``--stress-load N`` (``make test-stress``: 2)
runs them beside N busy processes. A failed test shows the end of every process log written
while it ran (the stack's ``<name>.log`` files, wherever under the session's temporary folder).
"""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ato_common.domains import NoFreeDomain, free_domain

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

#: what a failed test shows of each process log
LOG_LINES = 40
MAX_LOGS = 12
STARTED = pytest.StashKey[float]()
BASETEMP = pytest.StashKey[Path]()


def pytest_addoption(parser):
    parser.addoption('--stress-load', type=int, default=0, metavar='N',
                     help='run the tests beside N busy processes (make test-stress: 2)')


@pytest.fixture(scope='session', autouse=True)
def temporary_folder(request, tmp_path_factory):
    """The session's temporary folder, where a failed test's process logs are looked for."""
    request.config.stash[BASETEMP] = tmp_path_factory.getbasetemp()


@pytest.fixture(scope='session', autouse=True)
def stress_load(request):
    """``--stress-load N``: N processes that keep a CPU each busy for the whole session, and
    end with it however it ends: each polls whether its parent (this session) is still there,
    so a session killed before its teardown does not leave them loading the machine."""
    burn = (f'import os\nwhile os.getppid() == {os.getpid()}:\n'
            '    for _ in range(1_000_000): pass')
    busy = [subprocess.Popen([sys.executable, '-c', burn])
            for _ in range(request.config.getoption('stress_load'))]
    yield len(busy)
    for process in busy:
        process.kill()
        process.wait()


def pytest_runtest_setup(item):
    item.stash[STARTED] = time.time()


def process_logs(item) -> list[tuple[str, str]]:
    """(title, last lines) of every ``.log`` file under the session's temporary folder written
    since the test began, newest last."""
    started = item.stash.get(STARTED, None)
    base = item.config.stash.get(BASETEMP, None)
    if started is None or base is None:
        return []
    logs = []
    for path in base.rglob('*.log'):
        try:
            modified = path.stat().st_mtime
        except OSError:
            continue
        if modified >= started:
            logs.append((modified, path))
    sections = []
    for _, path in sorted(logs)[-MAX_LOGS:]:
        lines = path.read_text(errors='replace').splitlines()[-LOG_LINES:]
        sections.append((f'process log {Path(path).relative_to(base)}', '\n'.join(lines)))
    return sections


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if report.failed and item.get_closest_marker('integration') is not None:
        for title, text in process_logs(item):
            report.sections.append((title, text))
    return report


def pytest_collection_modifyitems(items):
    for item in items:
        if '/tests/' in str(item.fspath):
            item.add_marker(pytest.mark.integration)
            # With pytest-xdist (make test: -n 2 --dist loadgroup) the graph tests run one
            # after the other on one worker, each with the whole graph to itself, while the
            # other worker takes the unit tests: two graphs at once on two cores would make
            # the wall-clock limits of the real-time tests a matter of luck.
            item.add_marker(pytest.mark.xdist_group('graph'))


@pytest.fixture(scope='session')
def session_domain():
    """A domain held for the whole session by an exclusive lock file (ato_common.domains, the
    scheme run_scenario uses too), so two sessions (two CI jobs, a developer's run beside CI, a
    run_scenario) never share one. Tests within a session run one after the other and each stops
    its processes, so they can share it."""
    try:
        with free_domain() as domain:
            yield domain
    except NoFreeDomain as error:
        pytest.fail(str(error))


@pytest.fixture
def domain_id(session_domain):
    return session_domain
