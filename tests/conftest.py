"""Integration tests over rclpy: each test starts the real executables (as ``ros2 run`` would
find them) in a DDS domain that no other test session on this machine uses at the same time,
with discovery limited to this machine, so parallel runs never hear each other."""

import fcntl
import os
import tempfile
from pathlib import Path

import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

# Fast DDS derives its ports from the domain id; 1..232 are usable.
FIRST_DOMAIN, LAST_DOMAIN = 1, 232


def pytest_collection_modifyitems(items):
    for item in items:
        if '/tests/' in str(item.fspath):
            item.add_marker(pytest.mark.integration)


@pytest.fixture(scope='session')
def session_domain():
    """A domain held for the whole session by an exclusive lock file, so two sessions (two CI
    jobs, a developer's run beside CI) never share one. Tests within a session run one after
    the other and each stops its processes, so they can share it."""
    lock_dir = Path(tempfile.gettempdir())
    span = LAST_DOMAIN - FIRST_DOMAIN + 1
    start = os.getpid() % span
    for offset in range(span):
        candidate = FIRST_DOMAIN + (start + offset) % span
        handle = open(lock_dir / f'ato-ros-domain-{candidate}.lock', 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        try:
            yield candidate
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        return
    pytest.fail('no free ROS domain id: every one is locked by another test session')


@pytest.fixture
def domain_id(session_domain):
    return session_domain
