"""The ROS graph when one part goes away (issue 18): a lost observer never breaks the lockstep
loop, the runner ends at once naming a process that exited, a wait for a command is reported
and a restarted plant resumes, a node given another scenario than the plant's refuses, the last
step reaches its subscribers, --help, harmful parameters refused, two stacks in one domain."""

import signal
import subprocess
import time

import numpy as np
import pytest
from plant_driver import ControllerStandIn, plant_status
from sensor_msgs.msg import JointState

from ato_bringup.runner import RunFailed, run_lockstep
from ato_bringup.stack import EXECUTABLES, Stack, StackConfig, executable_path
from ato_common.commands import ros_command
from ato_common.conventions import status_in_namespace
from ato_ros.messages import to_time

PERIOD_NS = 100_000_000


def sim_s(monitor):
    return max(monitor.last_stamp_ns, 0) / 1e9


def wait_exit(stack, name, timeout_s=60.0):
    assert stack.spin_until(lambda: stack.exited(name), timeout_s), stack.log_tail(name)
    return stack.processes[name].returncode


def test_a_sigkilled_recorder_does_not_break_the_lockstep_loop(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         record_to=tmp_path / 'bag')
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor
        assert stack.spin_until(lambda: sim_s(monitor) >= 5.0, 120.0), stack.log_tail('plant')
        stack.processes['recorder'].send_signal(signal.SIGKILL)
        stack.processes['recorder'].wait()
        killed_at = sim_s(monitor)
        # The loop goes on without its observer: well past the kill and past the time DDS
        # takes to drop the dead reader (its samples stop being held for it).
        assert stack.spin_until(lambda: sim_s(monitor) >= killed_at + 60.0, 240.0), \
            stack.log_tail('plant') + stack.log_tail('controller') + stack.log_tail('profile')
        for name in ('plant', 'profile', 'controller'):
            assert not stack.exited(name), stack.log_tail(name)
        # its loss is reported in the plant's diagnostics
        assert stack.spin_until(lambda: any('an observer went away' in m
                                            for _, m, _ in plant_status(monitor)), 60.0)
        codes = stack.stop()
    assert {k: v for k, v in codes.items() if k != 'recorder'} == \
        {'plant': 0, 'profile': 0, 'controller': 0}


def test_the_runner_ends_at_once_naming_a_process_that_exited(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         record_to=tmp_path / 'bag')
    stop_recorder = {3.0: lambda stack: stack.processes['recorder'].send_signal(signal.SIGTERM)}
    with pytest.raises(RunFailed) as failed:
        run_lockstep(config, actions=stop_recorder, timeout_s=600.0)
    message = str(failed.value)
    assert message.startswith('recorder exited with code 0 at simulated'), message
    assert 'did not end within' not in message
    assert str(tmp_path / 'recorder.log') in message


def quiet(monitor, quiet_s: float = 1.0):
    """A condition for ``Stack.spin_until``: the monitor has taken no state, reference or
    command for ``quiet_s`` of wall time."""
    seen = {'counts': None, 'since': time.monotonic()}

    def condition() -> bool:
        counts = [monitor.counts[name] for name in ('state', 'reference', 'command')]
        if counts != seen['counts']:
            seen['counts'], seen['since'] = counts, time.monotonic()
        return time.monotonic() - seen['since'] >= quiet_s
    return condition


def test_a_wait_for_a_command_is_reported_and_a_restarted_plant_resumes(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         plant_params={'command_wait_limit_s': 1.0})
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor
        assert stack.spin_until(lambda: sim_s(monitor) >= 3.0, 120.0), stack.log_tail('plant')
        stack.processes['controller'].send_signal(signal.SIGKILL)
        stack.processes['controller'].wait()
        assert stack.spin_until(lambda: any(
            'waiting' in m and 'for the command of the step' in m and v['waiting_for_command_s']
            for _, m, v in plant_status(monitor)), 30.0), stack.log_tail('plant')
        assert 'simulated time stands still until a command comes' in stack.log_tail('plant')
        # a new controller takes the loop on from the step it stopped at
        stalled_at = sim_s(monitor)
        stack.start_process('controller', stack.node_params()['controller'])
        assert stack.spin_until(lambda: sim_s(monitor) >= stalled_at + 3.0, 120.0)
        # a restarted plant starts a new run, and controller and profile follow it
        stack.processes['plant'].send_signal(signal.SIGKILL)
        stack.processes['plant'].wait()
        # What the old run sent before the kill is taken first: on a loaded machine the test's
        # own spinning lags the loop by tens of steps (make test-stress counted 30 of the old
        # run's commands as the new run's). Nothing new comes once they are in.
        drained = stack.spin_until(quiet(monitor), 60.0)
        assert drained, f'the monitor still took messages of a dead plant: {monitor.counts}'
        commands = monitor.counts['command']
        stack.start_process('plant', stack.node_params()['plant'])
        # the controller sees a new run (its steps stamped from 0 again) and answers its steps
        assert stack.spin_until(lambda: monitor.counts['command'] >= commands + 30 and (
            'the plant started again' in stack.log_tail('controller', 200)), 120.0), (
            f'controller log:\n{stack.log_tail("controller", 200)}\nplant log:\n'
            f'{stack.log_tail("plant")}\ncommands {commands} -> {monitor.counts}, processes '
            f'{ {n: p.poll() for n, p in stack.processes.items()} }')
        assert min(monitor.samples) == 0 and monitor.samples[0].law == 'pid'
        codes = stack.stop()
    assert codes == {'plant': 0, 'profile': 0, 'controller': 0}


def test_controller_and_profile_refuse_a_plant_of_another_scenario(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        params = stack.node_params()
        stack.start_process('plant', params['plant'])
        stack.start_process('controller', {**params['controller'], 'scenario': 'jinan_xuzhou'})
        stack.start_process('profile', {**params['profile'], 'scenario': 'luo_xu_crh3'})
        for name, given in (('controller', 'jinan_xuzhou'), ('profile', 'luo_xu_crh3')):
            assert wait_exit(stack, name) == 2
            log = stack.log_tail(name)
            assert 'the plant simulates scenario short_line' in log and given in log, log
        codes = stack.stop()
    assert codes['plant'] == 0


def test_the_last_step_reaches_its_subscribers_before_the_plant_exits(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        controller = ControllerStandIn(stack)
        stack.start_process('plant', {'wait_for_subscribers': 1, 'end_time_s': 1.0})
        for k in range(9):
            controller.answer(k * PERIOD_NS, [100e3])
        monitor = stack.monitor
        # the last command: the plant steps to 1.0 s, publishes, and exits at once after that
        assert stack.spin_until(lambda: monitor.last_stamp_ns == 9 * PERIOD_NS, 30.0)
        msg = JointState(name=['traction'], effort=[100e3])
        msg.header.stamp = to_time(9 * PERIOD_NS)
        controller.publisher.publish(msg)
        assert wait_exit(stack, 'plant') == 0
        stack.spin_for(0.5)
        stamps = [k for k, _ in monitor.complete_samples()]
        assert stamps[-1] == 10 * PERIOD_NS
        assert np.all(np.diff(stamps) == PERIOD_NS)


def test_a_first_step_waiting_for_a_recorder_that_never_comes_says_so(tmp_path, domain_id):
    """A lockstep plant told to wait for a recorder (wait_for_recorders) that never subscribes
    (none started; or one recording a list of topics without /diagnostics) does not wait
    silently: after command_wait_limit_s it names the topic it waits on, again each period."""
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        stack.start_process('plant', {**stack.node_params()['plant'], 'wait_for_recorders': 1,
                                      'command_wait_limit_s': 0.5})

        def reports() -> int:
            return stack.log_tail('plant', 200).count(
                'of wall time: /ato/step_records has fewer subscribers than the first step '
                'waits for')
        assert stack.spin_until(lambda: reports() >= 2, 60.0), stack.log_tail('plant')
        assert stack.monitor.last_stamp_ns == -1, 'the plant stepped without its recorder'


@pytest.mark.parametrize('name', ['plant', 'profile', 'controller'])
def test_help_prints_usage_and_every_parameter_and_starts_nothing(name):
    package, executable = EXECUTABLES[name]
    done = subprocess.run([executable_path(package, executable), '--help'],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    # the command that works here: ros2 run with a full ROS 2, ato run with the wheels
    assert done.stdout.startswith(f'usage: {ros_command(f"run {package} {executable}")}')
    module = __import__(f'{package}.node', fromlist=['node'])
    params = getattr(module, 'PARAMS', None) or module.NODE_PARAMS + tuple(module.gain_params())
    for param in params:
        assert f'  {param.name} (' in done.stdout
    assert 'scenario' not in done.stderr  # nothing loaded, nothing logged


@pytest.mark.parametrize('name, params, reason', [
    ('profile', {'preview_horizon_s': 600.0, 'preview_step_s': 0.01},
     '60001 preview points per step, more than 100'),
    ('plant', {'lockstep': False, 'use_sim_time': True},
     'use_sim_time is true on a real-time plant'),
    ('plant', {'recorder_lead_s': 0.5},
     'recorder_lead_s 0.5 s is under the least lead of this loop, 1.6 s'),
])
def test_harmful_parameter_combinations_are_refused_with_the_reason(tmp_path, domain_id, name,
                                                                     params, reason):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        stack.start_process(name, params)
        assert wait_exit(stack, name) == 2
        assert reason in stack.log_tail(name)


def test_two_lockstep_stacks_in_one_domain_keep_to_themselves(tmp_path, domain_id):
    laws = {'east': 'pid', 'west': 'tan_weighted_mm'}
    stacks = {ns: Stack(StackConfig(scenario='short_line', controller=law, domain_id=domain_id,
                                    log_dir=tmp_path / ns, end_time_s=30.0, namespace=ns))
              for ns, law in laws.items()}
    try:
        for stack in stacks.values():
            stack.start()

        def both_done():
            for s in stacks.values():
                s.executor.spin_once(timeout_sec=0.01)
            return all(s.exited('plant') for s in stacks.values())
        deadline_ok = stacks['east'].spin_until(both_done, 300.0)
        assert deadline_ok, stacks['east'].log_tail('plant') + stacks['west'].log_tail('plant')
        for s in stacks.values():
            s.spin_for(0.3)
        for ns, stack in stacks.items():
            monitor = stack.monitor
            stamps = [k for k, _ in monitor.complete_samples()]
            assert stamps[0] == 0 and stamps[-1] == 300 * PERIOD_NS
            assert np.all(np.diff(stamps) == PERIOD_NS)  # one plant's steps, none of the other's
            assert {s.law for _, s in monitor.complete_samples()[:-1]} == {laws[ns]}
            names = {name for _, name, _, _ in monitor.diagnostics}
            # the stack's own statuses only (the monitor keeps those of its namespace)
            assert names == {'train_plant_node: simulation', 'ato_controller_node: law',
                             'profile_node: plan'}
            # the profile followed its own plant's clock only: one reference per step (ticks
            # of the other plant's clock would each get one more)
            assert monitor.counts['reference'] <= monitor.counts['state'] + 3, monitor.counts
            assert stack.log_tail('controller', 500).count('the plant started again') == 0
        codes = {ns: s.stop() for ns, s in stacks.items()}
        assert all(c == {'plant': 0, 'profile': 0, 'controller': 0} for c in codes.values())
    finally:
        for stack in stacks.values():
            stack.close()


def test_a_status_is_told_apart_by_its_namespace():
    assert status_in_namespace('train_plant_node: simulation', '/') == \
        'train_plant_node: simulation'
    assert status_in_namespace('east/train_plant_node: simulation', '/') is None
    assert status_in_namespace('east/train_plant_node: simulation', '/east') == \
        'train_plant_node: simulation'
    assert status_in_namespace('west/train_plant_node: simulation', '/east') is None
    assert status_in_namespace('east/inner/train_plant_node: simulation', '/east') is None
