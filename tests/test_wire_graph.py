"""The per-step topics go out as bytes packed by ato_ros.wire and are taken raw by the loop;
an ordinary subscriber (``ros2 topic echo``, a node of the user's) must still see ordinary,
standard messages with the suite's content."""

import math

from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from trajectory_msgs.msg import JointTrajectory

from ato_bringup.stack import Stack, StackConfig
from ato_ros.messages import (
    command_from_msg,
    from_time,
    qos_profile,
    reference_from_msg,
    state_from_msg,
    topic,
)

TYPES = {'clock': Clock, 'state': JointTrajectory, 'state_measured': JointTrajectory,
         'reference': JointTrajectory, 'command': JointState, 'actuators_commanded': JointState,
         'actuators_applied': JointState, 'distance_to_go': Float64, 'permitted_speed': Float64,
         'diagnostics': DiagnosticArray}
END_NS = 30_000_000_000


def test_typed_subscribers_see_standard_messages_of_every_per_step_topic(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path,
                         end_time_s=END_NS / 1e9, monitor='full')
    received = {key: [] for key in TYPES}
    with Stack(config) as stack:
        for key, kind in TYPES.items():
            stack.node.create_subscription(kind, topic(key).name, received[key].append,
                                           qos_profile(topic(key).qos))
        stack.start()
        assert stack.spin_until(lambda: stack.monitor.last_stamp_ns >= END_NS, 120.0), \
            'the run did not reach its end'
        stack.spin_for(0.5)
        samples = dict(stack.monitor.complete_samples())
    clock = [from_time(m.clock) for m in received['clock']]
    # (/clock keeps the last 10: a subscriber that lags may lose ticks, never get wrong ones; this
    # process takes ten typed topics at the loop's pace, and on a loaded machine it got a third
    # of the 300 ticks: a tenth of them shows the stream)
    assert clock[-1] == END_NS and clock == sorted(clock)
    assert all(t % 100_000_000 == 0 for t in clock) and len(set(clock)) > 30
    # the truth the raw monitor read is what the typed subscriber got, value for value
    states = {s.stamp_ns: s for s in map(state_from_msg, received['state'])}
    assert set(samples) <= set(states)
    for stamp, sample in samples.items():
        assert states[stamp].positions == sample.positions
        assert states[stamp].speeds == sample.speeds
        assert states[stamp].forces == sample.forces
    measured = [state_from_msg(m) for m in received['state_measured']]
    assert {s.stamp_ns for s in measured} >= set(samples)
    assert all(m.points[0].time_from_start.sec * 10**9 + m.points[0].time_from_start.nanosec
               == from_time(m.header.stamp) for m in received['state_measured'])
    references = [reference_from_msg(m) for m in received['reference']]
    assert len(references[0].points) > 1  # the preview
    by_stamp = {r.stamp_ns: r for r in references}
    for stamp, sample in samples.items():
        if stamp in by_stamp and not math.isnan(sample.ref_position):
            assert by_stamp[stamp].now.position == sample.ref_position
    commands = [command_from_msg(m, ('traction',)) for m in received['command']]
    assert {c.law for c in commands} == {'pid'}
    for stamp, sample in samples.items():
        if sample.command:
            assert next(c.forces for c in commands if c.stamp_ns == stamp) == sample.command
    for key in ('actuators_commanded', 'actuators_applied'):
        assert [tuple(m.name) for m in received[key]][-1] == ('traction',)
        assert not received[key][-1].position and len(received[key][-1].effort) == 1
    assert all(math.isfinite(m.data) for m in received['distance_to_go'])
    assert all(0 < m.data < 100 for m in received['permitted_speed'])
    assert len(received['distance_to_go']) > 250
    assert received['diagnostics']

