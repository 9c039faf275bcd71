"""Issue 17 and issue 13 defect 6 in lockstep, through the ROS graph: the profile reads the
measured state at its check instants (``replan_check_period_s``) and replans a late train or
resumes a standing one from there, deterministically (``profile_node.replan.LockstepPlans``).

A 60 s traction loss on a 15 km leg: with enough reserve the train still arrives within 2 s of
the timetable, the plan on ``/diagnostics`` says it was replanned, and the run is the offline
loop's run deciding as the node does, bit for bit (so its replans are at the same instants, from
the same positions); with too little reserve the expected delay is reported before the arrival.
After a watchdog emergency brake to standstill the reference resumes from where the train
stands, and the train then stops at the station before its end of authority."""

from __future__ import annotations

import math

import numpy as np
import pytest
from plant_driver import ControllerStandIn, plant_status
from sensor_msgs.msg import JointState

from ato_bringup.runner import run_lockstep
from ato_bringup.stack import Stack, StackConfig
from ato_common.braking_curves import RunSupervision
from ato_common.scenario import load_scenario
from ato_ros.messages import diagnostic_status, to_time
from ato_simulation.loop import run_offline
from profile_node.replan import CHECK_PERIOD_S
from profile_node.timetable import plan_summary

PERIOD_NS = 100_000_000
LENGTH_M = 15000.0
# Where the train counts as arrived: standing within this of the stopping point, m.
ARRIVED_WITHIN_M = 1.0

TRACTION_LOSS = """name: lockstep_traction_loss
description: a 60 s traction loss on one 15 km leg (test)
source: suite (test)
train: {{preset: crh3_luo_xu}}
line:
  name: lockstep_traction_loss
  length_m: 15000
  stations:
    - {{name: A, position_m: 0}}
    - {{name: B, position_m: 15000}}
  speed_limits:
    - {{start_m: 0, speed_kmh: 300}}
planning: {{max_acceleration_mps2: 0.4, service_deceleration_mps2: 0.5, max_jerk_mps3: 0.3,
           speed_margin_kmh: 5}}
timetable: {{strategy: timetable, supplement_percent: {supplement}}}
plant:
  failures:
    - {{actuator: traction, kind: loss, start_s: 80, end_s: 140}}
"""

STOP = """name: lockstep_resume
description: one 8 km leg, for a watchdog brake and the resume (test)
source: suite (test)
train: {preset: crh3_luo_xu}
line:
  name: lockstep_resume
  length_m: 9000
  stations:
    - {name: A, position_m: 0}
    - {name: B, position_m: 8000}
  speed_limits:
    - {start_m: 0, speed_kmh: 200}
planning: {max_acceleration_mps2: 0.4, service_deceleration_mps2: 0.5, max_jerk_mps3: 0.3,
           speed_margin_kmh: 5}
"""


def scenario_file(tmp_path, name, text) -> str:
    path = tmp_path / f'{name}.yaml'
    path.write_text(text)
    return str(path)


def arrival_s(times, positions, speeds, position_m: float) -> float:
    at = (np.abs(np.asarray(positions) - position_m) < ARRIVED_WITHIN_M) & \
        (np.abs(np.asarray(speeds)) < 0.01)
    assert at.any(), f'the train never stood at {position_m:g} m'
    return float(np.asarray(times)[np.argmax(at)])


def plan_statuses(outcome):
    """(stamp ns, message, values) of each plan the profile reported."""
    return [(stamp, message, values) for stamp, name, values, message in outcome.diagnostics
            if name == 'profile_node: plan']


def run_traction_loss(tmp_path, domain_id, supplement: float, logs: str = 'logs', **config):
    path = scenario_file(tmp_path, f'loss_{supplement:g}', TRACTION_LOSS.format(
        supplement=supplement))
    offline = run_offline(load_scenario(path), 'pid', replan_check_period_s=CHECK_PERIOD_S)
    # The lockstep run goes on to the replanned arrival (the runner ends at the first plan's).
    end = offline.times_s[-1]
    outcome = run_lockstep(StackConfig(scenario=path, domain_id=domain_id, end_time_s=end,
                                       log_dir=tmp_path / logs, **config))
    return outcome, offline


def states(outcome):
    times = np.array([k / 1e9 for k, _ in outcome.samples])
    return (times, np.array([s.positions[0] for _, s in outcome.samples]),
            np.array([s.speeds[0] for _, s in outcome.samples]))


def test_a_60_s_traction_loss_with_enough_reserve_is_replanned_on_time_as_offline(tmp_path,
                                                                                  domain_id):
    outcome, offline = run_traction_loss(tmp_path, domain_id, 10.0)
    times, positions, speeds = states(outcome)
    target = offline.plan.legs[0].target_arrival_s
    assert abs(arrival_s(times, positions, speeds, LENGTH_M) - target) <= 2.0
    plans = plan_statuses(outcome)
    assert [m for _, m, _ in plans] == ['timetable plan', 'replanned: the train was late']
    # the same decision as the offline loop's, from the same measured state: the same plan
    assert len(offline.replans) == 1
    replanned = diagnostic_status('plan', '', b'\x00', '', plan_summary(offline.replans[0]))
    assert plans[1][2] == {kv.key: kv.value for kv in replanned.values}
    assert float(plans[1][2]['expected_delay_s']) < 0.1
    # the whole run, bit for bit: the graph's lockstep loop is the offline loop
    count = len(offline.times_s)
    assert list(times[:count]) == list(offline.times_s)
    assert list(positions[:count]) == list(offline.positions)
    assert [s.ref_position for _, s in outcome.samples[:count]] == list(offline.ref_positions)
    # a* continuous and the jerk bounded across the replan
    start = offline.replans[0].trajectory.start_time
    assert offline.replans[0].trajectory.at(start).acceleration == pytest.approx(
        offline.plan.trajectory.at(start).acceleration, abs=1e-9)


def test_with_too_little_reserve_the_expected_delay_is_reported_before_the_arrival(tmp_path,
                                                                                   domain_id):
    # the lean monitor of run_scenario: its samples hold the reference the profile streamed
    # (taken in batches), so a summary's tracking is measured against the replanned curve
    outcome, offline = run_traction_loss(tmp_path, domain_id, 1.0, monitor='lean')
    times, positions, speeds = states(outcome)
    count = len(offline.times_s)
    assert [s.ref_position for _, s in outcome.samples[:count]] == list(offline.ref_positions)
    assert [s.ref_speed for _, s in outcome.samples[:count]] == list(offline.ref_speeds)
    target = offline.plan.legs[0].target_arrival_s
    arrival = arrival_s(times, positions, speeds, LENGTH_M)
    replans = [(stamp, values) for stamp, message, values in plan_statuses(outcome)
               if message.startswith('replanned')]
    assert replans, 'the late train was not replanned'
    stamp, values = replans[0]
    expected = float(values['expected_delay_s'])
    assert expected > 5.0
    assert stamp / 1e9 < target < arrival   # reported before the timetable's arrival
    assert arrival - target == pytest.approx(expected, abs=2.0)


def test_two_lockstep_runs_with_a_replan_are_identical_and_composed_equals_separate(
        tmp_path, domain_id):
    first, _ = run_traction_loss(tmp_path, domain_id, 10.0, 'first')
    composed, _ = run_traction_loss(tmp_path, domain_id, 10.0, 'composed', composed=True)
    assert [k for k, _ in composed.samples] == [k for k, _ in first.samples]
    for attribute in ('positions', 'speeds', 'ref_position', 'ref_speed', 'command'):
        # (the last step's command: the plant may end before the monitor hears it)
        a = [getattr(s, attribute) for _, s in first.samples[:-1]]
        b = [getattr(s, attribute) for _, s in composed.samples[:-1]]
        assert a == b, attribute  # bit-identical floats
    assert [m for _, m, _ in plan_statuses(composed)] == \
        [m for _, m, _ in plan_statuses(first)]


def test_after_a_watchdog_brake_to_standstill_the_reference_resumes_and_the_train_stops(
        tmp_path, domain_id):
    path = scenario_file(tmp_path, 'resume', STOP)
    scenario = load_scenario(path)
    leg = RunSupervision.for_scenario(scenario).legs[0]
    names = scenario.train.actuator_names
    config = StackConfig(scenario=path, domain_id=domain_id, log_dir=tmp_path / 'logs',
                         end_time_s=600.0)
    with Stack(config) as stack:
        params = stack.node_params()
        stack.start_process('profile', params['profile'])
        stack.start_process('plant', params['plant'])
        monitor = stack.monitor
        controller = ControllerStandIn(stack)
        # a faulty ATO: too little traction for 60 s (the train falls behind the reference),
        # then every command invalid (NaN), until the watchdog's emergency brake has stopped
        # the train
        k = 0
        for k in range(600):
            controller.answer(k * PERIOD_NS, [1e5], names)
        moving_at = monitor.samples[600 * PERIOD_NS]
        assert moving_at.speeds[0] > 5.0
        for k in range(600, 3000):
            stamp = k * PERIOD_NS
            assert stack.spin_until(lambda s=stamp: monitor.last_stamp_ns == s, 60.0)
            msg = JointState(name=list(names), effort=[math.nan])
            msg.header.stamp = to_time(stamp)
            controller.publisher.publish(msg)
            assert stack.spin_until(lambda s=stamp: monitor.last_stamp_ns > s, 30.0)
            if monitor.samples[stamp + PERIOD_NS].speeds[0] <= 0.0:
                break
        stood = monitor.samples[(k + 1) * PERIOD_NS]
        assert stood.speeds[0] == 0.0
        assert any('command watchdog' in m for _, m, _ in plant_status(monitor))
        # the real controller takes over from the step the plant waits at
        stack.start_process('controller', params['controller'])

        def stopped_at_b():
            samples = monitor.complete_samples()
            return samples and abs(samples[-1][1].positions[0] - 8000.0) < ARRIVED_WITHIN_M \
                and samples[-1][1].speeds[0] < 0.01
        assert stack.spin_until(lambda: stopped_at_b() or stack.exited('plant'), 300.0), \
            stack.log_tail('profile') + stack.log_tail('controller')
        stack.spin_for(0.5)  # what the plant sent before it ended
        samples = monitor.complete_samples()
        logs = '\n'.join(stack.log_tail(name) for name in ('plant', 'profile', 'controller'))
        resumes = [(stamp, values) for stamp, name, values, message in monitor.diagnostics
                   if name == 'profile_node: plan' and message.startswith('resumed')]
        assert len(resumes) == 1, stack.log_tail('profile')
        start = float(resumes[0][1]['plan_start_s'])
        # before the resume the reference ran far ahead of the standing train; after it, the
        # reference starts where the train stands and the train keeps close to it
        before = [s for t, s in samples if stood.positions and t / 1e9 < start
                  and s.speeds[0] == 0.0 and np.isfinite(s.ref_position)]
        assert before and before[-1].ref_position - before[-1].positions[0] > 50.0
        after = [s for t, s in samples if t / 1e9 >= start and np.isfinite(s.ref_position)]
        assert after
        assert abs(after[0].ref_position - after[0].positions[0]) < 1.0
        assert max(abs(s.ref_position - s.positions[0]) for s in after) < 5.0
        last = samples[-1]
        assert stopped_at_b(), (f'last sample at {last[0] / 1e9:.1f} s: '
                                f'{last[1].positions[0]:.2f} m, {last[1].speeds[0]:.3f} m/s\n'
                                + logs)
        assert max(s.positions[0] for _, s in samples) < leg.end_of_authority_m
