"""profile_node on its own over rclpy: it follows /clock in lockstep, publishes the distance to
go and the permitted speed of each tick, reports its plan once on diagnostics, a late
subscriber still gets the whole curve, and a malformed TTOBench line file stops it before it
starts."""

import json
import os
import subprocess

from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64, String
from trajectory_msgs.msg import JointTrajectory

from ato_bringup.stack import EXECUTABLES, Stack, StackConfig, executable_path
from ato_common.identity import scenario_identity
from ato_common.scenario import load_scenario
from ato_ros.messages import from_time, qos_profile, reference_from_msg, to_time, topic
from profile_node.planner import plan_reference

PERIOD_NS = 100_000_000


def subscribe(stack, name, msg_type, into):
    return stack.node.create_subscription(msg_type, topic(name).name, into.append,
                                          qos_profile(topic(name).qos))


def test_profile_follows_the_clock_and_a_late_subscriber_gets_the_whole_curve(tmp_path,
                                                                              domain_id):
    plan = plan_reference(load_scenario('short_line'))
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        distances, permitted = [], []
        subscribe(stack, 'distance_to_go', Float64, distances)
        subscribe(stack, 'permitted_speed', Float64, permitted)
        stack.start_process('profile', {'scenario': 'short_line', 'lockstep': True,
                                        'use_sim_time': True, 'wait_for_subscribers': 1,
                                        'preview_horizon_s': 2.0, 'preview_step_s': 1.0})
        clock = stack.node.create_publisher(Clock, topic('clock').name,
                                            qos_profile(topic('clock').qos))
        # as the plant does: its scenario, latched (the profile streams nothing before it)
        identity = stack.node.create_publisher(String, topic('identity').name,
                                               qos_profile(topic('identity').qos))
        identity.publish(String(data=scenario_identity(load_scenario('short_line'))))
        monitor = stack.monitor
        assert stack.spin_until(lambda: clock.get_subscription_count() > 0 and all(
            stack.node.count_publishers(topic(name).name) > 0
            for name in ('reference', 'distance_to_go', 'permitted_speed')), 60.0), \
            stack.log_tail('profile')
        ticks = [k * PERIOD_NS for k in range(30)] + [3000 * PERIOD_NS + k * PERIOD_NS
                                                      for k in range(5)]
        previous = None
        for tick in ticks:
            count, permitted_count = len(distances), len(permitted)
            known = set(monitor.samples)
            # lockstep: nothing for a tick before it is on /clock, then that tick's answer; a
            # tick is re-sent (as the plant does) while discovery is still matching at start-up
            for _ in range(20):
                clock.publish(Clock(clock=to_time(tick)))
                if stack.spin_until(lambda: len(distances) > count and tick in monitor.samples
                                    and len(permitted) > permitted_count, 1.0):
                    break
            else:
                raise AssertionError(f'no answer to tick {tick}\n{stack.log_tail("profile")}')
            sample = monitor.samples[tick]
            expected = plan.trajectory.at(tick / 1e9)
            assert sample.ref_position == expected.position
            assert sample.ref_speed == expected.speed
            assert permitted[-1].data == plan.permitted_speed(expected.position, tick / 1e9)
            target = plan.next_target(expected.position, tick / 1e9)
            assert distances[-1].data == target.location_m - expected.position
            # the reference is never published for a time the clock has not reached, except
            # the next tick sent ahead (one clock interval on)
            stack.spin_for(0.05)
            ahead = tick - previous if previous is not None else 0
            assert set(monitor.samples) - known <= {tick, tick + ahead}
            previous = tick
        assert min(permitted[-5:], key=lambda m: m.data).data > 0.0
        # The plan is reported on diagnostics once (it did not change), with its times.
        plans = [d for d in monitor.diagnostics if d[1] == 'profile_node: plan']
        assert len(plans) == 1, plans
        values = plans[0][2]
        assert values['strategy'] == 'fastest'
        assert float(values['stop.Terminus.arrival_s']) == float(
            f'{plan.stops[-1].arrival_s:.9g}')
        assert float(values['forecast.traction_energy_kwh']) > 0.0
        assert float(values['forecast.net_energy_kwh']) == float(
            values['forecast.traction_energy_kwh'])   # a preset regenerates nothing

        # A subscriber that joins now still receives the curve published at start-up.
        curves = []
        late = stack.node.create_subscription(JointTrajectory, topic('curve').name,
                                              curves.append, qos_profile(topic('curve').qos))
        assert stack.spin_until(lambda: curves, 20.0)
        curve = reference_from_msg(curves[0])
        assert from_time(curves[0].header.stamp) == 0
        assert curve.points[0].time_s == 0.0
        assert abs(curve.points[-1].time_s - plan.trajectory.end_time) < 1e-9  # ns stamps
        assert curve.points[-1].position == plan.stops[-1].station.position_m
        for stop in plan.stops:
            arrival = next(p for p in curve.points if abs(p.time_s - stop.arrival_s) < 1e-9)
            assert arrival.speed == 0.0
            assert abs(arrival.position - stop.station.position_m) < 0.01
        assert len(curve.points) >= int(plan.trajectory.end_time)
        stack.node.destroy_subscription(late)
        assert stack.stop(['profile'])['profile'] == 0


def start_lockstep_profile(stack, wait_for_subscribers: int):
    """The profile alone in lockstep beside the test's subscription to its step records, once
    it has subscribed to /clock and its reference and step records are seen: (the records
    received, the test's /clock publisher). That subscription stands for a recorder, which
    the profile is told to wait for (``wait_for_recorders``): matching is not symmetric, and
    the test seeing the profile's step records does not mean the profile has matched the
    test's subscription; records sent before it has are sent to nobody (a loaded stress run
    answered the tick without them)."""
    from std_msgs.msg import UInt8MultiArray

    records: list = []
    subscribe(stack, 'step_records', UInt8MultiArray, records)
    stack.start_process('profile', {'scenario': 'short_line', 'lockstep': True,
                                    'use_sim_time': True,
                                    'wait_for_subscribers': wait_for_subscribers,
                                    'wait_for_recorders': 1})
    clock = stack.node.create_publisher(Clock, topic('clock').name,
                                        qos_profile(topic('clock').qos))
    assert stack.spin_until(lambda: clock.get_subscription_count() > 0 and all(
        stack.node.count_publishers(topic(name).name) > 0
        for name in ('reference', 'step_records')), 60.0), stack.log_tail('profile')
    return records, clock


def publish_identity(stack):
    """The plant's identity of short_line, latched, as the plant publishes it."""
    identity = stack.node.create_publisher(String, topic('identity').name,
                                           qos_profile(topic('identity').qos))
    identity.publish(String(data=scenario_identity(load_scenario('short_line'))))
    return identity


def test_a_tick_that_came_before_the_plant_identity_is_answered_when_it_comes(tmp_path,
                                                                             domain_id):
    """The profile answers no tick before the plant's identity, and answers the latest one it
    had once the identity comes, its step records sent at once: an ATO node that does not wait
    for the reference lets the plant run on without re-sending a tick, and a recorder (here the
    test's subscription to the step records) vouches for nothing before the profile's records,
    so an unanswered tick held such a loop for good (CI, a loaded machine)."""
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        records, clock = start_lockstep_profile(stack, 1)
        tick = 7 * PERIOD_NS
        # Sent again until the identity, as the plant re-sends a tick it waits on: the test's
        # publisher has matched the profile's /clock subscription, but that subscription may
        # not have matched the publisher yet (matching is not symmetric), and a volatile reader
        # drops what was sent before it matched (a loaded `make test` lost the tick so). The
        # profile keeps the latest tick it had before the identity: this one.
        for _ in range(20):
            clock.publish(Clock(clock=to_time(tick)))
            stack.spin_for(0.1)
        assert tick not in stack.monitor.samples and not records, 'answered before the identity'
        publish_identity(stack)
        # the tick is not sent again: the profile answers the one it had
        assert stack.spin_until(lambda: tick in stack.monitor.samples and records, 30.0), \
            stack.log_tail('profile')
        assert stack.stop(['profile'])['profile'] == 0


def test_a_tick_held_for_a_missing_subscriber_is_answered_when_it_matches(tmp_path, domain_id):
    """A tick that comes after the plant's identity but before every subscriber the first
    reference waits for has matched (here a second one, wait_for_subscribers 2) is held, not
    dropped, and answered once that subscriber matches, without the plant sending it again
    (an ATO node of one's own that does not wait for the reference lets the plant run on, so a
    dropped tick held such a loop for good; seen on a loaded machine, where matching lags)."""
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path)
    with Stack(config) as stack:
        records, clock = start_lockstep_profile(stack, 2)
        identity = publish_identity(stack)
        assert stack.spin_until(lambda: identity.get_subscription_count() > 0, 60.0)
        stack.spin_for(1.0)  # the identity read
        tick = 7 * PERIOD_NS
        clock.publish(Clock(clock=to_time(tick)))  # reliable, matched: it reaches the profile
        stack.spin_for(2.0)
        assert tick not in stack.monitor.samples, 'answered with one subscriber of two'
        references: list = []
        subscribe(stack, 'reference', JointTrajectory, references)  # the second one
        assert stack.spin_until(lambda: tick in stack.monitor.samples and records, 30.0), \
            stack.log_tail('profile')
        assert stack.stop(['profile'])['profile'] == 0


def test_a_malformed_ttobench_line_stops_the_profile_before_it_starts(tmp_path, domain_id):
    track = tmp_path / 'track.json'
    track.write_text(json.dumps({
        'metadata': {'id': 'broken', 'library version': 'TTOBench v1.5'},
        'stops': {'unit': 'm', 'values': [0.0, 5000.0]},
        'speed limits': {'units': {'position': 'm', 'velocity': 'km/h'},
                         'values': [[0.0, 100], [-3.0, 80]]}}))
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text('name: broken\ntrain: {preset: crh3_luo_xu}\n'
                        'line: {ttobench: track.json}\n'
                        'planning: {max_acceleration_mps2: 0.5, service_deceleration_mps2: 0.5, '
                        'max_jerk_mps3: 0.5}\n')
    result = subprocess.run([executable_path(*EXECUTABLES['profile']), '--ros-args', '-p',
                             f'scenario:={scenario}'], capture_output=True, text=True,
                            timeout=60, env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert (f'{scenario}: {track}: speed limits.values[1]: positions must strictly increase, '
            'got 0 then -3 m') in result.stderr
    assert 'Traceback' not in result.stderr
    assert 'targets, reference ends' not in result.stderr + result.stdout  # never started
