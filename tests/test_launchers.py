"""The launchers run every law (issue 32): through ``ato launch`` (the launch file's arguments,
nodes and parameters, ato_bringup.launch_arguments) and ``run_scenario`` the plant follows the
scenario (mao_4car's 4-car unit gets the multi-car plant and the rigid-coupler law drives it to
its stops), a law that cannot drive its plant is refused with exit 2 and the reason, a peer
killed ends the launch naming it with every other node stopped inside launch's escalation time,
Ctrl-C at any moment ends it with 0 and no traceback, and each node's name is its own. With
``ros2`` on PATH (a full ROS 2 install) the same through ``ros2 launch``."""

import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]
LAUNCH = ['ato', 'launch', 'ato_bringup', 'ato.launch.py']


def environment(domain_id: int) -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(domain_id),
                PATH=f'{REPOSITORY / "scripts" / "bin"}:{os.environ["PATH"]}')


def started(command, domain_id, log: Path) -> subprocess.Popen:
    """``command`` in a session of its own (a terminal's Ctrl-C reaches its whole group)."""
    return subprocess.Popen(command, env=environment(domain_id), stdout=open(log, 'w'),
                            stderr=subprocess.STDOUT, start_new_session=True)


def wait_for(log: Path, text: str, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while text not in log.read_text():
        assert time.monotonic() < deadline, f'{text!r} not in:\n{log.read_text()}'
        time.sleep(0.1)


def discovered(command: list[str], domain_id: int, enough, timeout_s: float = 60.0
               ) -> list[str]:
    """The lines ``command`` lists once ``enough(lines)``, or at ``timeout_s``: a listing
    spins 2 s, and discovery of nodes and of their endpoints on a loaded machine takes longer,
    as a user sees by listing again."""
    deadline = time.monotonic() + timeout_s
    while True:
        lines = subprocess.run([*command, '--spin-time', '2'], env=environment(domain_id),
                               capture_output=True, text=True, timeout=60).stdout.splitlines()
        lines = [line for line in lines if line.strip()]
        if enough(lines) or time.monotonic() > deadline:
            return lines
        time.sleep(0.5)


def assert_ended_at_the_scenario_s_end(output: str, scenario: str = 'mao_4car') -> None:
    from ato_bringup.launch_arguments import resolve
    end_s = resolve({'scenario': scenario}).end_time_s
    ended = re.search(r'end of run at t = ([0-9.]+) s', output)
    assert ended, output
    assert end_s <= float(ended.group(1)) < end_s + 0.2, (end_s, ended.group(0))


def test_the_4_car_unit_is_driven_to_its_stops_and_a_mismatched_law_refused(tmp_path,
                                                                            domain_id):
    env = environment(domain_id)
    done = subprocess.run([*LAUNCH, 'scenario:=mao_4car', 'controller:=mao_multibody_rigid'],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert 'plant model multi_car' in done.stderr
    assert 'model multi_car, lockstep at 10 Hz' in done.stdout
    assert "train_plant_node ended (exit code 0)" in done.stderr
    assert_ended_at_the_scenario_s_end(done.stdout)  # no number given
    for command in ([*LAUNCH, 'scenario:=mao_4car', 'controller:=mao_2017'],
                    [*LAUNCH, 'scenario:=mao_4car', 'controller:=mao_multibody_rigid',
                     'model:=point_mass'],
                    ['ato', 'run', 'ato_bringup', 'run_scenario', '--scenario', 'mao_4car',
                     '--controller', 'mao_multibody_rigid', '--model', 'point_mass']):
        refused = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
        assert refused.returncode == 2, refused.stderr
        assert 'cannot drive scenario mao_4car' in refused.stderr
        assert 'started with pid' not in refused.stderr  # before any node
    # run_scenario: the same plant by default, each stop within the platform tolerance
    summary = subprocess.run(['ato', 'run', 'ato_bringup', 'run_scenario', '--scenario',
                              'mao_4car', '--controller', 'mao_multibody_rigid', '--no-record',
                              '--log-dir', str(tmp_path / 'run'), '--domain-id',
                              str(domain_id)], env=env, capture_output=True, text=True,
                             timeout=900)
    assert summary.returncode == 0, summary.stdout + summary.stderr  # a clean run
    assert 'plant multi_car' in summary.stderr
    assert 'stop errors           0' in summary.stdout


def test_a_killed_peer_ends_the_launch_naming_it_and_the_others_stop_in_time(tmp_path,
                                                                             domain_id):
    log = tmp_path / 'launch.log'
    launch = started([*LAUNCH, 'end_time_s:=never'], domain_id, log)
    try:
        wait_for(log, 'lockstep at')
        # each node once: the profile's helper node keeps a name of its own
        expected = ['/ato_controller_node', '/profile_node', '/profile_node_measured_sampler',
                    '/train_plant_node']
        names = discovered(['ato', 'node', 'list'], domain_id,
                           lambda names: set(names) >= set(expected))
        assert sorted(names) == expected, names
        ato = {'env': environment(domain_id), 'capture_output': True, 'text': True,
               'timeout': 60}
        got = subprocess.run(['ato', 'param', 'get', '/ato_controller_node', 'controller'], **ato)
        assert got.stdout.strip() == 'String value is: pid', got.stderr
        listed = subprocess.run(['ato', 'param', 'list', 'ato_controller_node'], **ato).stdout
        assert '  luo_xu.c1' in listed.splitlines() and '  controller' in listed.splitlines()
        command = '/ato/command [sensor_msgs/msg/JointState]'
        topics = discovered(['ato', 'topic', 'list', '-t'], domain_id,
                            lambda lines: command in lines)
        assert command in topics, topics
        echoed = subprocess.run(['ato', 'topic', 'echo', 'ato/command', '--once'], **ato)
        assert echoed.returncode == 0 and '  frame_id: pid' in echoed.stdout, echoed.stderr
        assert echoed.stdout.rstrip().endswith('---') and 'effort:' in echoed.stdout
        controller = subprocess.run(['pgrep', '-P', str(launch.pid), '-f',
                                     'lib/ato_controller_node/ato_controller_node'],
                                    capture_output=True, text=True).stdout.split()
        assert len(controller) == 1
        os.kill(int(controller[0]), signal.SIGKILL)
        code = launch.wait(timeout=60)
    finally:
        if launch.poll() is None:
            os.killpg(launch.pid, signal.SIGKILL)
    output = log.read_text()
    assert code == 1, output
    assert ('ato_controller_node exited with code -9 (killed by SIGKILL): the run has failed'
            in output)
    # the plant waited for the dead controller's acknowledgement less than launch's 5 s
    assert 'did not end' not in output and 'while stopping' not in output, output
    assert 'Traceback' not in output


@pytest.mark.parametrize('after_s', [0.5, 3.0, 'running'])
def test_ctrl_c_at_any_moment_ends_the_launch_with_0_and_no_traceback(tmp_path, domain_id,
                                                                      after_s):
    log = tmp_path / 'launch.log'
    launch = started([*LAUNCH, 'end_time_s:=never'], domain_id, log)
    try:
        if after_s == 'running':
            wait_for(log, 'lockstep at')
        else:
            time.sleep(after_s)  # the launch or its nodes still importing
        os.killpg(launch.pid, signal.SIGINT)  # what a terminal's Ctrl-C does
        code = launch.wait(timeout=60)
    finally:
        if launch.poll() is None:
            os.killpg(launch.pid, signal.SIGKILL)
    output = log.read_text()
    assert code == 0, output
    assert 'Traceback' not in output and 'KeyboardInterrupt' not in output, output
    assert 'error' not in output, output


@pytest.mark.skipif(shutil.which('ros2') is None, reason='ros2 launch needs a full ROS 2 '
                    '(the wheels have no launch package; ato launch runs the same)')
def test_ros2_launch_runs_the_4_car_unit_and_refuses_a_mismatched_law(domain_id):
    env = environment(domain_id)
    ros2 = ['ros2', 'launch', 'ato_bringup', 'ato.launch.py', 'scenario:=mao_4car']
    done = subprocess.run([*ros2, 'controller:=mao_multibody_rigid'], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert_ended_at_the_scenario_s_end(done.stdout + done.stderr)
    refused = subprocess.run([*ros2, 'controller:=mao_2017'], env=env, capture_output=True,
                             text=True, timeout=120)
    assert refused.returncode == 1  # the only failing code a launch file can give
    assert 'mao_2017 cannot drive scenario mao_4car' in refused.stdout + refused.stderr
