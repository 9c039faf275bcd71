"""The recorder's acknowledgements of step records at the edges of a run (issue 31): the first
one, one that a plant's subscription matches only after it was sent, and an ATO node of one's
own that the recorder saw before the loop's step records."""

import rclpy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, UInt8MultiArray

from ato_bringup.stack import Stack, StackConfig
from ato_common.types import Command
from ato_ros import wire
from ato_ros.messages import from_time, qos_profile, topic
from ato_ros.step_records import ACK_PERIOD_S, Bundle
from recorder.bag import read_messages

S = 1_000_000_000
STEP = 100_000_000


def _bundle(topic_name: str, stamps, encode) -> bytes:
    bundle = Bundle(period_s=1e9, wall_period_s=1e9)
    for stamp in stamps:
        bundle.add(topic_name, stamp, encode(stamp))
    return bundle.take()


def test_the_first_acknowledgement_waits_for_every_publisher_of_step_records(tmp_path,
                                                                            domain_id):
    """The profile's bundles come before the plant's: an acknowledgement of them alone would
    let the plant run a lead past a file without its /clock and state. The first
    acknowledgement waits until each publisher of the namespace's step records has a bundle in
    the file."""
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        spec = topic('step_records')
        profile = stack.node.create_publisher(UInt8MultiArray, spec.name, qos_profile(spec.qos))
        plant = stack.node.create_publisher(UInt8MultiArray, spec.name, qos_profile(spec.qos))
        acknowledged = []
        stack.node.create_subscription(Header, topic('recorded').name, acknowledged.append,
                                       qos_profile(topic('recorded').qos))
        stack.start_process('recorder', {}, ['-o', str(tmp_path / 'bag')])
        assert stack.spin_until(lambda: profile.get_subscription_count() >= 1
                                and plant.get_subscription_count() >= 1, 60.0), \
            stack.log_tail('recorder')
        stamps = [7 * S + k * STEP for k in range(round(ACK_PERIOD_S * 10) + 3)]
        for stamp in stamps:
            profile.publish(_bundle('/ato/distance_to_go', [stamp], wire.encode_float64))
        written = 'recording /ato/distance_to_go [std_msgs/msg/Float64] from the step records'
        assert stack.spin_until(lambda: written in stack.log_tail('recorder', 200), 60.0), \
            stack.log_tail('recorder')
        stack.spin_for(0.5)  # an acknowledgement made with the bundle would be here by now
        assert acknowledged == [], 'acknowledged before the plant\'s records were in the file'
        plant.publish(_bundle('/clock', [stamps[3]], wire.encode_clock))
        assert stack.spin_until(lambda: acknowledged, 30.0), stack.log_tail('recorder')
        # the oldest of the two publishers' records, which both are in the file
        assert from_time(acknowledged[0].stamp) == stamps[3]
        assert stack.stop()['recorder'] == 0


def test_a_plant_that_matches_the_recorder_late_still_gets_its_acknowledgement(tmp_path,
                                                                              domain_id):
    """Discovery is not symmetric: the plant may see the recorder's publisher of ``recorded``
    (and count it as a recorder to wait for) before the recorder's side has matched the plant's
    subscription. An acknowledgement sent in that window reached nobody, no new step records
    came (the plant held), and a run waited for the recorder for ever (make test-stress: the
    plant held at 1.8 s for 300 s, the recorder's file holding those 1.8 s). A subscription that
    matches after the recorder has acknowledged receives its latest acknowledgement."""
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        spec = topic('step_records')
        plant = stack.node.create_publisher(UInt8MultiArray, spec.name, qos_profile(spec.qos))
        stack.start_process('recorder', {}, ['-o', str(tmp_path / 'bag')])
        assert stack.spin_until(lambda: plant.get_subscription_count() >= 1, 60.0), \
            stack.log_tail('recorder')
        stamps = [k * STEP for k in range(round(ACK_PERIOD_S * 10) + 3)]
        plant.publish(_bundle('/clock', stamps, wire.encode_clock))
        written = 'recording /clock [rosgraph_msgs/msg/Clock] from the step records'
        assert stack.spin_until(lambda: written in stack.log_tail('recorder', 200), 60.0), \
            stack.log_tail('recorder')
        stack.spin_for(1.0)  # acknowledged by now, to no subscriber
        acknowledged = []
        stack.node.create_subscription(Header, topic('recorded').name, acknowledged.append,
                                       qos_profile(topic('recorded').qos))
        assert stack.spin_until(lambda: acknowledged, 30.0), 'no acknowledgement reached ' \
            'a subscription made after it was sent'
        assert from_time(acknowledged[-1].stamp) == stamps[-1]
        assert stack.stop()['recorder'] == 0


def _command(stamp: int) -> bytes:
    return wire.encode_command(Command(stamp, ('traction',), (1e4,), 'own_ato'))


def test_an_ato_node_seen_before_the_step_records_loses_no_command(tmp_path, domain_id):
    """An ATO node of one's own publishes ato/command before the loop's step records appear: the
    recorder has subscribed to it as to any topic, keeps that subscription when the step
    records come (a new one would lose what is published until it matches), and acknowledges
    as its commands are written, not only when a bundle comes (the plant, held, sends none)."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    loop = rclpy.create_node('loop', context=context)  # a participant of its own
    try:
        _record_an_own_ato(tmp_path, domain_id, loop)
    finally:
        loop.destroy_node()
        rclpy.shutdown(context=context)


def _record_an_own_ato(tmp_path, domain_id: int, loop) -> None:
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        commands = stack.node.create_publisher(JointState, topic('command').name,
                                               qos_profile(topic('command').qos))
        acknowledged = []
        stack.node.create_subscription(Header, topic('recorded').name, acknowledged.append,
                                       qos_profile(topic('recorded').qos))
        # a take period long enough that commands wait in the subscription for it
        stack.start_process('recorder', {}, ['-o', str(tmp_path / 'bag'), '--take-period', '1'])
        subscribed = 'recording /ato/command [sensor_msgs/msg/JointState]'
        assert stack.spin_until(lambda: subscribed in stack.log_tail('recorder', 200), 60.0), \
            stack.log_tail('recorder')
        # the Stack's monitor subscribes to the commands too
        assert stack.spin_until(lambda: commands.get_subscription_count() >= 2, 60.0)
        sent = [1 * S + k * STEP for k in range(50)]  # 1.0 s to 5.9 s
        for stamp in sent[:10]:
            commands.publish(_command(stamp))
        spec = topic('step_records')
        records = loop.create_publisher(UInt8MultiArray, spec.name, qos_profile(spec.qos))
        for stamp in sent[10:20]:  # while the recorder discovers the step records
            commands.publish(_command(stamp))
            stack.spin_for(0.02)
        assert stack.spin_until(lambda: records.get_subscription_count() >= 1, 60.0), \
            stack.log_tail('recorder')
        # the loop's records run to 5.9 s; the commands written lag behind, at 2.9 s
        records.publish(_bundle('/clock', sent, wire.encode_clock))
        assert stack.spin_until(lambda: acknowledged, 30.0), stack.log_tail('recorder')
        for stamp in sent[20:]:  # no bundle comes now: the commands move what is written on
            commands.publish(_command(stamp))
        assert stack.spin_until(
            lambda: acknowledged and from_time(acknowledged[-1].stamp) == sent[-1], 30.0), \
            ([from_time(a.stamp) for a in acknowledged], stack.log_tail('recorder'))
        assert stack.stop()['recorder'] == 0
    recorded = [wire.decode_joint_state(m.data)[0]
                for m in read_messages(tmp_path / 'bag', ['/ato/command'])]
    assert recorded == sent, sorted(set(sent) - set(recorded))
