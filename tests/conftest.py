"""Integration tests over rclpy: each test starts the real executables (as ``ros2 run`` would
find them) in a DDS domain of its own, with discovery limited to this machine, so tests and CI
runs in parallel never hear each other."""

import itertools
import os

import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

_domains = itertools.count()


def pytest_collection_modifyitems(items):
    for item in items:
        if '/tests/' in str(item.fspath):
            item.add_marker(pytest.mark.integration)


@pytest.fixture
def domain_id():
    """A domain not used by any other test of this session nor (most likely) of another
    session: the base depends on the process id."""
    base = int(os.environ.get('ATO_TEST_DOMAIN_BASE', 100 + (os.getpid() % 12) * 10))
    return base + next(_domains) % 10
