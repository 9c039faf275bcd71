"""Each node on its own over rclpy: install layout, bad input, real-time mode."""

import math
import os
import re
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_prefix, get_package_share_directory
from plant_driver import ControllerStandIn, plant_status

from ato_bringup.stack import EXECUTABLES, Stack, StackConfig, executable_path

PACKAGES = ['ato_common', 'train_plant_node', 'profile_node', 'ato_controller_node',
            'ato_bringup']


@pytest.mark.parametrize('package', PACKAGES)
def test_packages_are_installed_as_ros2_run_expects(package):
    prefix = Path(get_package_prefix(package))
    assert (prefix / 'share/ament_index/resource_index/packages' / package).is_file()
    manifest = ET.parse(Path(get_package_share_directory(package)) / 'package.xml').getroot()
    assert manifest.get('format') == '3'
    assert manifest.find('export/build_type').text == 'ament_python'
    for pkg, exe in EXECUTABLES.values():
        if pkg == package:
            assert os.access(prefix / 'lib' / pkg / exe, os.X_OK)
    if package == 'ato_bringup':
        assert os.access(prefix / 'lib/ato_bringup/run_scenario', os.X_OK)
        assert (Path(get_package_share_directory(package)) / 'launch/ato.launch.py').is_file()


@pytest.mark.parametrize('name', ['plant', 'profile', 'controller'])
def test_a_malformed_scenario_stops_the_node_before_it_starts(tmp_path, name, domain_id):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('name: bad\ntrain: {preset: crh3_luo_xu}\n'
                   'line: {name: l, length_m: 1000, stations: [{name: A, position_m: 0}, '
                   '{name: B, position_m: nowhere}], speed_limits: [{start_m: 0, speed_kmh: 80}]}\n'
                   'planning: {max_acceleration_mps2: 0.5, service_deceleration_mps2: 0.5, '
                   'max_jerk_mps3: 0.5}\n')
    result = subprocess.run([executable_path(*EXECUTABLES[name]), '--ros-args', '-p',
                             f'scenario:={bad}'], capture_output=True, text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert f"{bad}: line.stations[1].position_m: must be a number, got 'nowhere'" in \
        result.stderr
    assert 'Traceback' not in result.stderr


def test_the_multi_car_model_with_a_single_mass_train_is_refused_at_start(domain_id):
    result = subprocess.run([executable_path(*EXECUTABLES['plant']), '--ros-args', '-p',
                             'model:=multi_car'], capture_output=True, text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert "model multi_car: train 'crh3_luo_xu' has no multi-car description" in result.stderr
    assert 'Traceback' not in result.stderr


def test_a_failed_sensor_car_the_plant_model_does_not_have_is_refused_at_start(tmp_path,
                                                                             domain_id):
    bad = tmp_path / 'sensor.yaml'
    bad.write_text('name: sensor\ntrain: {preset: crh2_4car_mao}\n'
                   'line: {name: l, length_m: 1000, stations: [{name: A, position_m: 0}, '
                   '{name: B, position_m: 900}], speed_limits: [{start_m: 0, speed_kmh: 80}]}\n'
                   'planning: {max_acceleration_mps2: 0.5, service_deceleration_mps2: 0.5, '
                   'max_jerk_mps3: 0.5}\n'
                   'plant: {sensors: {speed: {failed_from_s: 10, failed_cars: [train]}}}\n')
    result = subprocess.run([executable_path(*EXECUTABLES['plant']), '--ros-args', '-p',
                             f'scenario:={bad}', '-p', 'model:=multi_car'], capture_output=True,
                            text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert ("error: plant.sensors.speed.failed_cars[0]: car 'train' is not a car of the "
            'multi_car model; valid: car_1, car_2, car_3, car_4') in result.stderr
    assert 'Traceback' not in result.stderr


def test_an_unknown_controller_at_start_is_refused_with_the_valid_names(domain_id):
    result = subprocess.run([executable_path(*EXECUTABLES['controller']), '--ros-args', '-p',
                             'controller:=bogus'], capture_output=True, text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert re.search(r'valid: (.*, )?luo_xu, (.*, )?pid', result.stderr)


@pytest.mark.parametrize('arguments, message', [
    (['gains:=best'], "gains 'best' is not valid; valid: published, tuned"),
    (['gains:=tuned', 'controller:=liu_li', 'scenario:=liu_li_2020'],
     'no tuned gains of liu_li for the train crh380al_liu_li'),
])
def test_a_configuration_of_gains_that_cannot_be_had_is_refused_at_start(domain_id, arguments,
                                                                          message):
    command = [executable_path(*EXECUTABLES['controller']), '--ros-args']
    for argument in arguments:
        command += ['-p', argument]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert message in result.stderr
    assert 'Traceback' not in result.stderr


@pytest.mark.parametrize('name, parameter', [('controller', 'rate_hz'),
                                             ('plant', 'control_rate_hz')])
def test_an_out_of_range_parameter_at_start_is_refused_naming_it(domain_id, name, parameter):
    result = subprocess.run([executable_path(*EXECUTABLES[name]), '--ros-args', '-p',
                             f'{parameter}:=-5.0'], capture_output=True, text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert f'Parameter {parameter} out of range' in result.stderr
    assert 'Traceback' not in result.stderr


def test_plant_rejects_bad_commands_and_keeps_running(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        controller = ControllerStandIn(stack)
        stack.start_process('plant', {'scenario': 'short_line', 'wait_for_subscribers': 1})
        monitor = stack.monitor
        controller.answer(0, [math.nan])
        controller.answer(100_000_000, [1.0, 2.0], ['traction', 'extra'])
        controller.answer(200_000_000, [1.0], ['brake'])
        controller.answer(300_000_000, [250e3])
        stack.spin_until(lambda: len(plant_status(monitor)) >= 4, 10.0)
        messages = [m for _, m, _ in plant_status(monitor)]
        assert any('not finite' in m for m in messages)
        assert any('do not match the actuators' in m for m in messages)
        assert plant_status(monitor)[-1][2]['rejected_commands'] == '3'
        states = monitor.complete_samples()
        assert [k for k, _ in states] == [0, 100_000_000, 200_000_000, 300_000_000, 400_000_000]
        assert states[-1][1].forces == (250e3,)  # the first valid command is applied
        assert all(math.isfinite(v) for _, s in states for v in s.positions + s.speeds)
        assert not stack.exited('plant')
        assert stack.stop()['plant'] == 0


def test_real_time_mode_runs_on_wall_clock_timers(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         lockstep=False)
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor

        def commands():
            return [s for _, s in sorted(monitor.samples.items()) if s.command]

        # Process start-up takes from under a second to several on a loaded machine.
        assert stack.spin_until(lambda: len(commands()) > 0 and monitor.last_stamp_ns > 0, 120.0)
        first_commands, first_states = len(commands()), len(monitor.complete_samples())
        first_stamp = monitor.last_stamp_ns
        stack.spin_for(8.0)
        states = monitor.complete_samples()
        # simulated time keeps to the wall clock
        assert (monitor.last_stamp_ns - first_stamp) / 1e9 == pytest.approx(8.0, abs=0.5)
        refs = [s for _, s in sorted(monitor.samples.items()) if not math.isnan(s.ref_speed)]
        # 10 Hz control and 100 Hz plant for 8 s of wall time
        assert 60 <= len(commands()) - first_commands <= 90
        assert 500 <= len(states) - first_states <= 900
        assert all(s.law == 'pid' for s in commands())
        latest_state, latest_ref = states[-1][1], refs[-1]
        assert latest_state.positions[0] > 0.0
        assert abs(latest_state.speeds[0] - latest_ref.ref_speed) < 1.0
        assert abs(latest_state.positions[0] - latest_ref.ref_position) < 10.0
        codes = stack.stop()
    assert codes == {'controller': 0, 'profile': 0, 'plant': 0}


MULTI_CAR_SCENARIO = """
name: multi_car_failures
train: {preset: crh2_4car_mao}
line: {name: l, length_m: 50000, stations: [{name: A, position_m: 0}, {name: B, position_m: 40000}],
       speed_limits: [{start_m: 0, speed_kmh: 300}]}
planning: {max_acceleration_mps2: 0.5, service_deceleration_mps2: 0.5, max_jerk_mps3: 0.5}
plant:
  failures:
    - {actuator: car_3, kind: stuck, start_s: 0.2, force_n: 1.0e+4}
  sensors:
    speed: {failed_from_s: 0.3, failed_cars: [car_2]}
"""


def test_multi_car_plant_publishes_cars_actuators_failures_and_takes_injections(tmp_path,
                                                                              domain_id):
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory

    from ato_ros.messages import from_time, qos_profile, topic
    scenario = tmp_path / 'multi.yaml'
    scenario.write_text(MULTI_CAR_SCENARIO)
    config = StackConfig(scenario=str(scenario), domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        received = {'actuators_commanded': {}, 'actuators_applied': {}, 'state_measured': {}}
        for key in received:
            kind = JointTrajectory if key == 'state_measured' else JointState
            stack.node.create_subscription(
                kind, topic(key).name,
                lambda msg, key=key: received[key].__setitem__(from_time(msg.header.stamp), msg),
                qos_profile(topic(key).qos))
        controller = ControllerStandIn(stack)
        stack.start_process('plant', {'scenario': str(scenario), 'model': 'multi_car',
                                      'wait_for_subscribers': 1})
        names = ('car_2', 'car_3')
        controller.answer(0, [20e3, 20e3], names)
        controller.answer(100_000_000, [math.nan, 1.0], names)       # rejected, held
        controller.answer(200_000_000, [20e3], names[:1])            # wrong length
        controller.answer(300_000_000, [25e3, 25e3], names)
        results = stack.set_parameters('train_plant_node', {
            'inject_failure': '{actuator: car_2, kind: partial, effectiveness: 0.5}'})
        assert results[0].successful, results[0].reason
        bad = stack.set_parameters('train_plant_node', {
            'inject_failure': '{actuator: car_9, kind: loss}'})[0]
        assert not bad.successful and "unknown actuator 'car_9'" in bad.reason
        controller.answer(400_000_000, [25e3, 25e3], names)
        stack.spin_until(lambda: 500_000_000 in received['actuators_applied'], 10.0)
        applied = {k: tuple(m.effort) for k, m in received['actuators_applied'].items()}
        commanded = {k: tuple(m.effort) for k, m in received['actuators_commanded'].items()}
        assert applied[100_000_000] == (20e3, 20e3)
        assert commanded[300_000_000] == (20e3, 20e3)          # the rejected ones were not held
        assert applied[300_000_000] == (20e3, 1e4)              # car_3 stuck from 0.2 s
        assert commanded[400_000_000] == (25e3, 25e3)
        assert applied[500_000_000] == (12.5e3, 1e4)           # car_2 at half effectiveness
        states = stack.monitor.complete_samples()
        assert len(states[-1][1].positions) == 4 and states[-1][1].forces[1:3] == (12.5e3, 1e4)
        measured = received['state_measured']
        assert not math.isnan(measured[200_000_000].points[0].velocities[1])
        assert math.isnan(measured[300_000_000].points[0].velocities[1])   # failed sensor: NaN
        assert not math.isnan(measured[300_000_000].points[0].velocities[0])
        assert all(math.isfinite(v) for _, s in states for v in s.speeds)  # truth separate
        assert any('not finite' in m for _, m, _ in plant_status(stack.monitor))
        assert not stack.exited('plant')
        assert stack.stop()['plant'] == 0
