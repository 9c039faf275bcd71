"""Fail-safe reactions over rclpy: command watchdog, ATP supervision, a controller killed and
restarted in real time."""

import math
import signal

import pytest
from plant_driver import ControllerStandIn, plant_status

from ato_bringup.stack import Stack, StackConfig
from ato_ros.messages import qos_profile, to_time, topic


def test_lockstep_watchdog_brakes_on_invalid_commands_and_recovers(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        controller = ControllerStandIn(stack)
        stack.start_process('plant', {'wait_for_subscribers': 1, 'watchdog_periods': 2,
                                      'emergency_periods': 4})
        monitor = stack.monitor
        for k in range(20):
            controller.answer(k * 100_000_000, [250e3])  # get moving
        for k in range(20, 26):
            controller.answer(k * 100_000_000, [math.nan])
        controller.answer(26 * 100_000_000, [250e3])
        stack.spin_until(lambda: any('released' in m or 'running' in m
                                     for _, m, _ in plant_status(monitor)[-1:]), 10.0)
        traction = 300e3
        forces = {k // 100_000_000: s.forces[0] for k, s in monitor.complete_samples()}
        # states carry the force applied up to them
        assert forces[21] == 250e3                       # first invalid: still the last command
        assert forces[23] == -0.9 * 510e3                 # service brake (0.9 m/s^2 x 510 t)
        # emergency brake: traction cut, the brake building up linearly over T_be (2 s)
        assert 0.0 >= forces[24] > forces[25] > forces[26] > -1.2 * 510e3
        assert forces[26] - forces[25] == pytest.approx(-0.1 / 2.0 * 1.2 * 510e3)
        assert forces[27] == pytest.approx(min(250e3, traction))  # valid again: released
        messages = [m for _, m, _ in plant_status(monitor)]
        assert any('watchdog: service brake' in m for m in messages)
        assert any('watchdog: emergency brake' in m for m in messages)


def test_atp_intervention_cannot_be_overridden_by_the_ato(tmp_path, domain_id):
    line = tmp_path / 'slow.yaml'
    line.write_text(
        'name: slow\ntrain: {preset: crh3_luo_xu}\n'
        'line: {name: slow, length_m: 20000, stations: [{name: A, position_m: 0}, '
        '{name: B, position_m: 19000}], speed_limits: [{start_m: 0, speed_kmh: 30}]}\n'
        'planning: {max_acceleration_mps2: 0.3, service_deceleration_mps2: 0.5, '
        'max_jerk_mps3: 0.3}\n')
    config = StackConfig(scenario=str(line), domain_id=domain_id, log_dir=tmp_path / 'logs')
    with Stack(config) as stack:
        controller = ControllerStandIn(stack)
        stack.start_process('plant', {'scenario': str(line), 'wait_for_subscribers': 1})
        monitor = stack.monitor
        for k in range(900):  # full traction all the way: the ATO tries to overspeed
            controller.answer(k * 100_000_000, [300e3])
        stack.spin_for(0.5)
        states = monitor.complete_samples()
        speeds = [s.speeds[0] for _, s in states]
        assert max(speeds) * 3.6 < 37.5 + 0.5  # EBI of a 30 km/h ceiling: + dV_ebi 7.5 km/h
        braking = [s.forces[0] for _, s in states if s.forces[0] < 0.0]
        assert braking and min(braking) >= -1.2 * 510e3  # the emergency brake, building up
        status = plant_status(monitor)
        assert any(m.startswith('ATP emergency brake intervention') for _, m, _ in status)
        assert int(status[-1][2]['atp_interventions']) >= 1


def test_controller_killed_and_restarted_in_real_time(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         lockstep=False)
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor
        assert stack.spin_until(lambda: monitor.counts['command'] > 0, 120.0)
        stack.spin_for(3.0)
        stack.processes['controller'].send_signal(signal.SIGKILL)
        stack.processes['controller'].wait()
        assert stack.spin_until(lambda: any('emergency brake' in m
                                            for _, m, _ in plant_status(monitor)), 30.0)
        # the states published with that report show the emergency brake applied
        assert stack.spin_until(
            lambda: monitor.complete_samples()[-1][1].forces[0] == -1.2 * 510e3, 10.0)
        commands_before = monitor.counts['command']
        stack.start_process('controller', stack.node_params()['controller'])
        assert stack.spin_until(lambda: monitor.counts['command'] > commands_before + 30, 120.0)
        # released, the ATO drives again (on a loaded machine the restarted controller may
        # still miss a few control periods, each a watchdog reaction of its own: the release
        # is awaited, not sampled at one moment)
        assert stack.spin_until(
            lambda: plant_status(monitor)[-1][1] == 'running'
            and monitor.complete_samples()[-1][1].forces[0] > -0.9 * 510e3, 60.0), \
            (plant_status(monitor)[-3:], stack.log_tail('plant'))
        assert all(math.isfinite(v) for _, s in monitor.complete_samples()
                   for v in s.positions + s.speeds)
        codes = stack.stop()
    assert codes['plant'] == 0 and codes['profile'] == 0


def test_controller_commands_nothing_on_a_stale_measurement(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         lockstep=False)
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor
        assert stack.spin_until(lambda: monitor.counts['command'] > 10, 120.0)
        stack.processes['plant'].send_signal(signal.SIGKILL)
        stack.processes['plant'].wait()

        def stale_reported():
            return any(name == 'ato_controller_node: law' and 'stale' in message
                       for _, name, _, message in monitor.diagnostics)
        assert stack.spin_until(stale_reported, 30.0)
        commands = monitor.counts['command']
        stack.spin_for(1.5)
        assert monitor.counts['command'] == commands  # nothing commanded on an old measurement
        codes = stack.stop(['controller', 'profile'])
    assert codes == {'controller': 0, 'profile': 0}


def test_controller_never_commands_nan_on_a_failed_sensor(tmp_path, domain_id):
    """A test node plays the plant: the measured speed turns NaN (a failed sensor) and back.
    Like the plant, it says which scenario it simulates, and neither the controller nor the
    profile sends anything (a command, a reference) before it has read that: on a loaded
    machine the first states can be taken before the identity, and the harness's refusal case
    saw the controller command a plant of another scenario once before refusing it (make
    test-stress)."""
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String
    from trajectory_msgs.msg import JointTrajectory

    from ato_common.identity import scenario_identity
    from ato_common.scenario import load_scenario
    from ato_common.types import TrainState
    from ato_ros.messages import state_to_msg

    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        node = stack.node
        identity = node.create_publisher(String, topic('identity').name,
                                         qos_profile(topic('identity').qos))
        clock_pub = node.create_publisher(Clock, '/clock', qos_profile(topic('clock').qos))
        state_pub = node.create_publisher(JointTrajectory, topic('state_measured').name,
                                          qos_profile(topic('state_measured').qos))
        params = stack.node_params()
        stack.start_process('profile', {**params['profile'], 'wait_for_subscribers': 1})
        stack.start_process('controller', {**params['controller'], 'wait_for_subscribers': 1})
        monitor = stack.monitor
        # the controller takes the measured state; the profile's ticks come from /clock (in
        # lockstep neither uses use_sim_time, so /clock has the profile's subscription only)
        assert stack.spin_until(lambda: state_pub.get_subscription_count() >= 1
                                and clock_pub.get_subscription_count() >= 1, 120.0)
        speeds = [0.0] * 5 + [math.nan] * 10 + [math.inf] * 5 + [0.5] * 5
        first = state_to_msg(TrainState(0, ('train',), (0.0,), (0.0,), (0.0,), (0.0,)))
        for _ in range(20):  # the first step, said again, before the identity
            clock_pub.publish(Clock(clock=to_time(0)))
            state_pub.publish(first)
            stack.spin_for(0.1)
        assert 0 not in monitor.samples or not monitor.samples[0].command, \
            'commanded before the plant said which scenario it simulates'
        assert 0 not in monitor.samples or math.isnan(monitor.samples[0].ref_position), \
            'a reference before the plant said which scenario it simulates'
        identity.publish(String(data=scenario_identity(load_scenario('short_line'))))
        for k, speed in enumerate(speeds):
            stamp = k * 100_000_000
            state = TrainState(stamp, ('train',), (0.0,), (speed,), (0.0,), (0.0,))
            for _ in range(200):  # like the plant: say it again until the command comes
                clock_pub.publish(Clock(clock=to_time(stamp)))
                state_pub.publish(state_to_msg(state))
                if stack.spin_until(lambda: stamp in monitor.samples
                                    and monitor.samples[stamp].command, 0.2):
                    break
            else:
                pytest.fail(f'no command for step {k}')
        stack.spin_for(1.5)
        commands = [monitor.samples[k * 100_000_000].command[0] for k in range(len(speeds))]
        assert all(math.isfinite(c) for c in commands)
        assert commands[5:20] == [commands[4]] * 15   # held while the sensor is failed
        faults = [message for _, name, _, message in monitor.diagnostics
                  if name == 'ato_controller_node: law' and 'needs the measured speed' in message]
        assert faults
