"""A stop while a process is still starting is a clean exit (no traceback); a node told to stop
is gone within the stop budget, under a launch's 5 s escalation from SIGINT to SIGTERM; --help
names the command that works here."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from ato_ros import lifecycle
from ato_ros.lifecycle import node_usage
from ato_ros.params import Param

STILL_IMPORTING = textwrap.dedent('''
    import signal, sys, time
    from ato_ros.interrupts import quiet_until_running
    # Python's own SIGINT handling, even when started from a shell that ignores SIGINT (a
    # background job): SIG_IGN is inherited and Python then installs no handler of its own
    signal.signal(signal.SIGINT, signal.default_int_handler)
    if sys.argv[1] == 'quiet':
        quiet_until_running()
    print('importing', flush=True)
    time.sleep(30)  # stands for the seconds rclpy, numba and scipy take to import
''')


@pytest.mark.parametrize('sent', [signal.SIGINT, signal.SIGTERM])
def test_a_stop_while_importing_ends_the_process_with_0_and_no_traceback(sent):
    def stopped(mode):
        process = subprocess.Popen([sys.executable, '-c', STILL_IMPORTING, mode],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert process.stdout.readline() == 'importing\n'
        process.send_signal(sent)
        out, err = process.communicate(timeout=30)
        return process.returncode, err
    code, err = stopped('quiet')
    assert code == 0, err
    assert 'Traceback' not in err and f'stopped while starting ({sent.name})' in err
    if sent == signal.SIGINT:  # what the nodes did before: KeyboardInterrupt, killed by SIGINT
        code, err = stopped('default')
        assert code == -signal.SIGINT and 'KeyboardInterrupt' in err


def test_a_node_told_to_stop_has_what_is_left_of_the_budget_for_its_teardown():
    assert lifecycle.STOP_BUDGET_S < 5.0  # launch's sigterm_timeout
    assert lifecycle.teardown_limit_s(None) == lifecycle.TEARDOWN_LIMIT_S  # ended by itself
    now = time.monotonic()
    assert lifecycle.teardown_limit_s(now) == pytest.approx(lifecycle.STOP_BUDGET_S, abs=0.1)
    # its outputs took 2 s (the plant's final delivery under a launcher): 2 s are left
    assert lifecycle.teardown_limit_s(now - 2.0) == pytest.approx(
        lifecycle.STOP_BUDGET_S - 2.0, abs=0.1)
    # past the budget, the teardown still gets its least time
    assert lifecycle.teardown_limit_s(now - 60.0) == lifecycle.LEAST_TEARDOWN_S


def test_help_names_ros2_where_it_is_on_path_and_ato_elsewhere(tmp_path, monkeypatch):
    params = (Param('scenario', 'short_line', 'the scenario'),)
    monkeypatch.setenv('PATH', str(tmp_path))
    assert node_usage('profile_node', 'profile_node', 'A node.', params).startswith(
        'usage: ato run profile_node profile_node [-h]')
    ros2 = tmp_path / 'ros2'
    ros2.write_text('#!/bin/sh\n')
    ros2.chmod(0o755)
    assert node_usage('profile_node', 'profile_node', 'A node.', params).startswith(
        'usage: ros2 run profile_node profile_node [-h]')
    assert os.environ['PATH'] == str(tmp_path)
