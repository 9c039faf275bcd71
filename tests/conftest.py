"""Integration tests over rclpy: each test starts the real executables (as ``ros2 run`` would
find them) in a DDS domain that no other test session on this machine uses at the same time,
with discovery limited to this machine, so parallel runs never hear each other."""

import os

import pytest

from ato_common.domains import NoFreeDomain, free_domain

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


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
