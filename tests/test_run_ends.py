"""How a run through the graph ends (issue 29 items 6 and 7, issue 32): a killed plant ends a
lockstep run naming the process, the signal and the simulated time reached, the progress bar
left where the run was; a real-time run (run_scenario --real-time) ends the same way when a peer
dies, with its simulated time, and completes with a summary otherwise; run_scenario hosts an ATO
node of the user's (--controller-command); Ctrl-C stops run_scenario without a traceback."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ato_bringup.launch_arguments import resolve
from ato_bringup.runner import RunFailed, run_lockstep
from ato_bringup.stack import StackConfig

EXAMPLE = Path(__file__).resolve().parents[1] / 'examples' / 'external_ato' / 'p_ato_node.py'


def kill(name):
    def action(stack):
        stack.processes[name].send_signal(signal.SIGKILL)
    return action


def simulated_s(message: str) -> float:
    return float(re.search(r'at simulated ([0-9.]+) s', message).group(1))


def test_a_killed_plant_ends_the_run_with_its_signal_and_simulated_time(tmp_path, domain_id,
                                                                        capfd):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with pytest.raises(RunFailed) as failed:
        run_lockstep(config, actions={20.0: kill('plant')}, progress=True)
    message = str(failed.value)
    assert message.startswith('plant exited with code -9 (killed by SIGKILL) at simulated '), \
        message
    end_s = resolve({}).end_time_s  # short_line's end
    assert 20.0 <= simulated_s(message) < 100.0 and f'of {end_s:.1f} s' in message
    assert str(tmp_path / 'plant.log') in message
    bar = capfd.readouterr().err
    assert f'{end_s:.1f}/{end_s:.1f}' not in bar and '100%' not in bar  # no jump to the end


def test_a_real_time_run_ends_when_a_peer_dies_naming_it_and_the_simulated_time(tmp_path,
                                                                                domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         lockstep=False, end_time_s=120.0)
    with pytest.raises(RunFailed) as failed:
        run_lockstep(config, actions={5.0: kill('controller')}, timeout_s=300.0)
    message = str(failed.value)
    assert message.startswith('controller exited with code -9 (killed by SIGKILL) at '
                              'simulated '), message
    assert 5.0 <= simulated_s(message) < 30.0 and 'of 120.0 s' in message  # run time, not epoch


def run_scenario(*args, domain_id, timeout=900):
    return subprocess.run([sys.executable, '-m', 'ato_bringup.run_scenario', '--no-record',
                           '--domain-id', str(domain_id), *args],
                          capture_output=True, text=True, timeout=timeout)


def test_run_scenario_runs_in_real_time_to_the_end_with_a_summary(tmp_path, domain_id):
    done = run_scenario('--real-time', '--end-time', '15', '--log-dir', str(tmp_path),
                        domain_id=domain_id)
    assert done.returncode in (0, 3), done.stderr  # 3: the stops are after the end
    assert 'in real time' in done.stderr
    simulated = float(re.search(r'simulated time +([0-9.]+) s', done.stdout).group(1))
    assert 14.0 <= simulated <= 16.0, done.stdout
    rms = float(re.search(r'speed error +RMS ([0-9.]+) km/h', done.stdout).group(1))
    assert rms < 5.0, done.stdout  # judged against the plan at each state's run time


def test_run_scenario_hosts_an_ato_node_of_the_user_s(tmp_path, domain_id):
    command = f'{sys.executable} {EXAMPLE}'
    done = run_scenario('--controller-command', command, '--end-time', '120', '--log-dir',
                        str(tmp_path), domain_id=domain_id)
    assert done.returncode in (0, 3), done.stdout + done.stderr
    assert f'controller            external ({command})' in done.stdout
    assert 'watchdog brakes       0' in done.stdout
    log = (tmp_path / 'controller.log').read_text()  # started with the scenario it drives
    assert 'refusing' not in log


def test_ctrl_c_stops_run_scenario_and_every_process_without_a_traceback(tmp_path, domain_id):
    log = tmp_path / 'run.log'
    process = subprocess.Popen([sys.executable, '-m', 'ato_bringup.run_scenario', '--no-record',
                                '--domain-id', str(domain_id), '--log-dir', str(tmp_path)],
                               stdout=open(log, 'w'), stderr=subprocess.STDOUT,
                               start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while 'running short_line' not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(3.0)  # the nodes importing or running
        os.killpg(process.pid, signal.SIGINT)  # a terminal's Ctrl-C: the whole group
        code = process.wait(timeout=60)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    output = log.read_text()
    assert code == 128 + signal.SIGINT, output
    assert 'stopped (SIGINT): every process of the run has ended' in output
    assert 'Traceback' not in output and 'KeyboardInterrupt' not in output, output
    leftover = subprocess.run(['pgrep', '-s', str(process.pid)], capture_output=True, text=True)
    assert leftover.stdout == '', 'processes of the run left running'
