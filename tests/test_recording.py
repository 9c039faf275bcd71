"""Recording runs to MCAP, reading them with independent readers, replaying, recovering."""

import os
import signal
import subprocess

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from trajectory_msgs.msg import JointTrajectory

from ato_bringup.runner import run_lockstep
from ato_bringup.stack import Stack, StackConfig, executable_path
from ato_ros.messages import from_time
from recorder.bag import bag_file, bag_info, read_messages, recover
from recorder.report import load_run, run_metrics

LOOP_TOPICS = ['/clock', '/train/state', '/train/state/measured', '/ato/reference',
               '/ato/reference/curve', '/ato/distance_to_go', '/ato/permitted_speed',
               '/ato/command', '/diagnostics']


@pytest.fixture(scope='module')
def recorded(tmp_path_factory, session_domain):
    folder = tmp_path_factory.mktemp('recorded')
    outcome = run_lockstep(StackConfig(scenario='short_line', domain_id=session_domain,
                                       end_time_s=200.0,
                                       log_dir=folder / 'logs', record_to=folder / 'bag'))
    return outcome, folder / 'bag'


def test_recording_holds_every_message_the_run_published(recorded):
    outcome, bag = recorded
    info = bag_info(bag)
    assert outcome.exit_codes['recorder'] == 0
    assert set(LOOP_TOPICS) <= set(info.topics)
    # The plant counts what it published, steps re-sent while the others came up included.
    published = int([values for _, name, values, _ in outcome.diagnostics
                     if name == 'train_plant_node: simulation'][-1]['steps_published'])
    assert published >= 2001
    # The observation topics (published only while subscribed) too: the recorder gets each step.
    for topic in ('/clock', '/train/state', '/train/state/measured',
                  '/train/actuators/commanded', '/train/actuators/applied'):
        assert info.topics[topic].message_count == published, topic
    assert info.topics['/ato/reference'].message_count == outcome.counts['reference']
    assert info.topics['/ato/command'].message_count == outcome.counts['command']
    stamps = sorted({state_stamp(m) for m in read_messages(bag, ['/train/state'])})
    assert stamps == [k for k, _ in outcome.samples]  # every step
    assert info.topics['/ato/reference/curve'].message_count == 1
    assert info.end_ns >= 200_000_000_000  # log time is simulated time


def test_unstamped_topics_are_logged_at_simulated_time(recorded):
    """The stack's recorder takes its time from the /clock it records (``--sim-time``): an
    unstamped message is logged at the simulated time of a step, never at the wall clock."""
    _, bag = recorded
    ticks = {m.log_time_ns for m in read_messages(bag, ['/clock'])} | {0}
    for topic in ('/ato/distance_to_go', '/ato/permitted_speed'):
        times = [m.log_time_ns for m in read_messages(bag, [topic])]
        assert len(times) > 2000, topic
        assert set(times) <= ticks, topic
        assert times == sorted(times), topic


def test_the_mcap_library_with_mcap_ros2_decodes_every_message(recorded):
    _, bag = recorded
    with open(bag_file(bag), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert reader.get_header().profile == 'ros2'
        assert all(s.encoding == 'ros2msg' and s.data for s in summary.schemas.values())
        decoded = sum(1 for _ in reader.iter_decoded_messages())
    assert decoded == sum(summary.statistics.channel_message_counts.values())


def test_rosbags_opens_the_bag_folder_and_decodes_every_message(recorded):
    _, bag = recorded
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        total = sum(c.msgcount for c in reader.connections)
        decoded = sum(1 for c, _, raw in reader.messages()
                      if typestore.deserialize_cdr(raw, c.msgtype) is not None)
    assert decoded == total == bag_info(bag).message_count


def test_report_from_the_recording_gives_the_run_metrics(recorded):
    outcome, bag = recorded
    from_bag = run_metrics(load_run(bag))
    assert from_bag.rms_speed_error_kmh == pytest.approx(outcome.metrics.rms_speed_error_kmh,
                                                         rel=1e-9)
    assert from_bag.max_position_error_m == pytest.approx(outcome.metrics.max_position_error_m,
                                                          rel=1e-9)
    assert from_bag.traction_energy_kwh == pytest.approx(outcome.metrics.traction_energy_kwh,
                                                         rel=1e-9)
    assert list(from_bag.stop_errors_m.values()) == \
        pytest.approx(list(outcome.metrics.stop_errors_m.values()))


def test_record_replay_record_gives_the_same_bytes(recorded, tmp_path, domain_id):
    _, bag = recorded
    again = tmp_path / 'again'
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        stack.config.log_dir.mkdir(parents=True, exist_ok=True)
        stack.start_process('recorder', {}, ['-o', str(again), *LOOP_TOPICS])
        replay = subprocess.run(
            [executable_path('recorder', 'replay'), str(bag), '--rate', '100',
             '--wait-for-subscribers', '1', '--topics', *LOOP_TOPICS],
            env=stack.env, capture_output=True, text=True, timeout=300)
        assert replay.returncode == 0, replay.stderr
        assert stack.stop()['recorder'] == 0
    for topic in LOOP_TOPICS:
        first = [m.data for m in read_messages(bag, [topic])]
        second = [m.data for m in read_messages(again, [topic])]
        assert second == first, topic


def test_sigkill_loses_at_most_the_last_second(tmp_path, domain_id):
    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path / 'logs',
                         lockstep=False, record_to=tmp_path / 'bag')
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor
        assert stack.spin_until(lambda: monitor.counts['command'] > 0, 120.0)
        # the window starts when the recorder has subscribed to the state (its start-up varies)
        assert stack.spin_until(lambda: 'recording /train/state ' in stack.log_tail('recorder',
                                                                                    200), 60.0)
        # 4 s of states after it (at 100 Hz), however loaded the machine
        subscribed = len(monitor.samples)
        assert stack.spin_until(lambda: len(monitor.samples) >= subscribed + 400, 60.0)
        killed_at_ns = monitor.last_stamp_ns
        monitor_samples = monitor.complete_samples()
        stack.processes['recorder'].send_signal(signal.SIGKILL)
        stack.processes['recorder'].wait()
        stack.stop()
    recover(tmp_path / 'bag')
    recorded = [state_stamp(m) for m in read_messages(tmp_path / 'bag', ['/train/state'])]
    assert recorded, 'nothing recovered'
    assert killed_at_ns - recorded[-1] < 1_000_000_000
    # everything the monitor saw from the first recorded state until a second before the kill
    seen = [k for k, _ in monitor_samples if recorded[0] <= k <= killed_at_ns - 1_000_000_000]
    assert len(seen) > 200 and set(seen) <= set(recorded), (
        f'{len(seen)} states seen from the first recorded one ({recorded[0]} ns) to a second '
        f'before the kill ({killed_at_ns} ns); {len(recorded)} recorded')


def test_replay_with_offset_topic_selection_and_remap(recorded, tmp_path, domain_id):
    _, bag = recorded
    out = tmp_path / 'remapped'
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        stack.config.log_dir.mkdir(parents=True, exist_ok=True)
        stack.start_process('recorder', {}, ['-o', str(out), '/replayed/state', '/clock'])
        replay = subprocess.run(
            [executable_path('recorder', 'replay'), str(bag), '--rate', '200',
             '--start-offset', '150', '--topics', '/train/state', '--wait-for-subscribers', '1',
             '--ros-args', '-r', '/train/state:=/replayed/state'],
            env=stack.env, capture_output=True, text=True, timeout=300)
        assert replay.returncode == 0, replay.stderr
        assert stack.stop()['recorder'] == 0
    info = bag_info(out)
    states = sorted(state_stamp(m) for m in read_messages(out, ['/replayed/state']))
    assert set(info.topics) == {'/replayed/state', '/clock'}  # the recorded /clock goes along
    # The offset counts in log time, as rosbag2's does (the suite's stamped topics are logged at
    # their stamp, by default).
    offset_ns = bag_info(bag).start_ns + 150_000_000_000
    expected = sorted(state_stamp(m) for m in read_messages(bag, ['/train/state'])
                      if m.log_time_ns >= offset_ns)
    assert states == expected
    assert min(states) >= 149_900_000_000 and max(states) == 200_000_000_000
    assert len(states) == info.topics['/replayed/state'].message_count >= 500


def state_stamp(message) -> int:
    return from_time(deserialize_message(message.data, JointTrajectory).header.stamp)


UNSTAMPED = ('/ato/distance_to_go', '/ato/permitted_speed')


def test_the_step_records_give_the_bytes_a_recorder_of_each_topic_gets(tmp_path, domain_id):
    """The stack's recorder takes the per-step topics from the loop nodes' step records; a
    second recorder beside it (``--no-step-records``) subscribes to each of them. From the
    moment both record, they hold the same messages, byte for byte, at the same log times, and
    the first does not record the bundles themselves."""
    # the loop starts once the second recorder takes the truth, the reference and the command
    # too (it is not waited for on the step records: it takes none); at nice 19 on a loaded
    # machine it can discover the controller's command a second after the other topics, when
    # a 100 s run is nearly over
    config = StackConfig(scenario='short_line', domain_id=domain_id, end_time_s=100.0,
                         log_dir=tmp_path / 'logs', record_to=tmp_path / 'bundled',
                         watched_by=('state', 'reference', 'command'))
    with Stack(config) as stack:
        stack.start_process('recorder_each', {}, ['-o', str(tmp_path / 'each'), '--sim-time',
                                                  '--no-step-records'],
                            ['-r', '__node:=recorder_each'], kind='recorder')
        stack.start()
        # the plant waits for the nice-19 recorder: on a loaded machine the run is slow, and
        # only a run whose simulated time stands still for a minute has failed (once started:
        # five processes start first)
        assert stack.spin_until(lambda: stack.monitor.last_stamp_ns >= 0
                                or stack.exited('plant'), 300.0), stack.log_tail('plant')
        while not stack.exited('plant'):
            stamp = stack.monitor.last_stamp_ns
            assert stack.spin_until(lambda s=stamp: stack.exited('plant')
                                    or stack.monitor.last_stamp_ns != s, 60.0), \
                stack.log_tail('plant')
        codes = stack.stop()
    assert codes['recorder'] == 0 and codes['recorder_each'] == 0
    bundled, each = bag_info(tmp_path / 'bundled'), bag_info(tmp_path / 'each')
    per_step = ['/clock', '/train/state', '/train/state/measured', '/ato/reference',
                '/ato/distance_to_go', '/ato/permitted_speed', '/ato/command',
                '/train/actuators/commanded', '/train/actuators/applied']
    assert set(per_step) <= set(bundled.topics) and set(per_step) <= set(each.topics)
    assert '/ato/step_records' not in bundled.topics and '/ato/step_records' not in each.topics
    for topic in per_step:
        assert bundled.topics[topic].type == each.topics[topic].type, topic
        assert bundled.topics[topic].offered_qos_profiles == \
            each.topics[topic].offered_qos_profiles, topic
        a = [(m.log_time_ns, m.data) for m in read_messages(tmp_path / 'bundled', [topic])]
        b = [(m.log_time_ns, m.data) for m in read_messages(tmp_path / 'each', [topic])]
        assert len(a) >= 1001, topic  # every step (the stack's recorder is waited for)
        # the other one, not waited for, misses the first steps: from when both record
        since = max(a[0][0], b[0][0]) + 1_000_000_000
        a, b = [x for x in a if x[0] >= since], [x for x in b if x[0] >= since]
        assert len(b) > 300, (topic, len(b))
        if topic in UNSTAMPED:
            # logged at their step by the step records, at the last /clock received by the
            # other recorder (its time may be a step off): the same messages
            a, b = [d for _, d in a], [d for _, d in b]
            n = min(len(a), len(b)) - 2
            assert any(a[i:i + n] == b[j:j + n] for i in range(3) for j in range(3)), \
                topic
        elif topic == '/clock':
            # keep last 10 (the conventions' /clock QoS): a subscriber that lags more than ten
            # steps loses ticks, as any /clock subscriber would; what it got, the bundles hold,
            # in order (a step the plant published again while it waited, resend_period_s on a
            # loaded machine, is there twice, one after the other)
            assert set(b) <= set(a) and a == sorted(a), topic
        else:
            assert a == b, topic


def test_a_malformed_step_record_is_reported_and_the_recording_goes_on(tmp_path, domain_id):
    """A bundle that does not parse is named in the recorder's log and dropped; the recorder
    lives on and writes the next good bundle's messages under their own topics."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import UInt8MultiArray

    from ato_ros.messages import qos_profile, topic
    from ato_ros.step_records import Bundle

    state = JointTrajectory()
    state.header.stamp.sec = 7
    data = serialize_message(state)
    good = Bundle()
    good.add('/train/state', 7_000_000_000, data)
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        publisher = stack.node.create_publisher(UInt8MultiArray, topic('step_records').name,
                                                qos_profile(topic('step_records').qos))
        stack.start_process('recorder', {}, ['-o', str(tmp_path / 'bag')])
        assert stack.spin_until(lambda: publisher.get_subscription_count() >= 1, 60.0), \
            stack.log_tail('recorder')
        publisher.publish(b'\x00\x01\x00\x00' + b'\xff' * 12)  # a layout that does not parse
        publisher.publish(good.take())
        assert stack.spin_until(lambda: 'recording /train/state' in stack.log_tail('recorder'),
                                30.0), stack.log_tail('recorder')
        log = stack.log_tail('recorder')
        assert stack.stop()['recorder'] == 0
    assert 'step records not read: step records:' in log, log
    recorded = list(read_messages(tmp_path / 'bag', ['/train/state']))
    assert [(m.log_time_ns, m.data) for m in recorded] == [(7_000_000_000, data)]


def test_replay_of_a_broken_file_says_what_is_wrong(tmp_path, domain_id):
    bogus = tmp_path / 'bogus.mcap'
    bogus.write_bytes(b'not a bag')
    result = subprocess.run([executable_path('recorder', 'replay'), str(bogus)],
                            capture_output=True, text=True, timeout=60,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert 'is not an MCAP file' in result.stderr and 'Traceback' not in result.stderr


def test_two_sources_of_simulated_time_are_refused_naming_both(tmp_path, domain_id):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id))
    done = subprocess.run([executable_path('recorder', 'recorder'), '-o', str(tmp_path / 'bag'),
                           '--sim-time', '--ros-args', '-p', 'use_sim_time:=true'],
                          env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert '--sim-time and use_sim_time' in done.stderr + done.stdout
    assert 'Traceback' not in done.stderr


def test_the_recorder_acknowledges_step_records_once_they_are_in_its_file(tmp_path, domain_id):
    """The acknowledgement (``ato/recorded``, a std_msgs/Header) names the recorder and the
    stamp up to which the namespace's step records are written; a copy of the file taken then,
    recovered, holds them: what is acknowledged survives a SIGKILL."""
    import shutil

    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header, UInt8MultiArray

    from ato_ros.messages import qos_profile, topic
    from ato_ros.step_records import ACK_PERIOD_S, Bundle

    state = JointTrajectory()
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path / 'logs')) as stack:
        publisher = stack.node.create_publisher(UInt8MultiArray, topic('step_records').name,
                                                qos_profile(topic('step_records').qos))
        acknowledged = []
        stack.node.create_subscription(Header, topic('recorded').name, acknowledged.append,
                                       qos_profile(topic('recorded').qos))
        stack.start_process('recorder', {}, ['-o', str(tmp_path / 'bag')])
        assert stack.spin_until(lambda: publisher.get_subscription_count() >= 1, 60.0), \
            stack.log_tail('recorder')
        # a bundle a step, over one acknowledgement period and a step more
        stamps = [7_000_000_000 + k * 100_000_000 for k in range(round(ACK_PERIOD_S * 10) + 2)]
        for stamp in stamps:
            bundle = Bundle()
            state.header.stamp.sec, state.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            bundle.add('/train/state', stamp, serialize_message(state))
            publisher.publish(bundle.take())
        # the first bundle is acknowledged, then one ACK_PERIOD_S of stamps later
        wanted = [s for s in stamps if s == stamps[0] or
                  s - stamps[0] >= round(ACK_PERIOD_S * 1e9)][:2]
        assert stack.spin_until(lambda: len(acknowledged) >= 2, 30.0), stack.log_tail('recorder')
        assert [(from_time(a.stamp), a.frame_id) for a in acknowledged] == \
            [(s, '/recorder') for s in wanted]
        shutil.copytree(tmp_path / 'bag', tmp_path / 'copy')  # as a SIGKILL would leave it
        assert stack.stop()['recorder'] == 0
    recover(tmp_path / 'copy')
    in_copy = [m.log_time_ns for m in read_messages(tmp_path / 'copy', ['/train/state'])]
    assert in_copy[:len(stamps[:3])] == stamps[:3] and max(in_copy) >= wanted[-1]


def test_a_recorder_that_falls_behind_holds_the_lockstep_and_loses_nothing(tmp_path,
                                                                             domain_id):
    """Back-pressure (plant parameter recorder_lead_s): a recorder stopped (SIGSTOP, as a
    recorder starved of CPU) holds the plant at most the lead past what it acknowledged; the
    plant reports the wait and names the recorder; the loop goes on once the recorder does,
    and the bag holds every step. What the file holds while the loop waits (a copy, recovered,
    as a SIGKILL would leave it) is within the lead of the last step published."""
    import shutil

    from std_msgs.msg import Header

    from ato_ros.messages import qos_profile, topic
    from ato_ros.step_records import LEAD_S

    # long enough that the loop (a few seconds of wall time) is under way at the SIGSTOP
    config = StackConfig(scenario='short_line', domain_id=domain_id, end_time_s=900.0,
                         log_dir=tmp_path / 'logs', record_to=tmp_path / 'bag',
                         plant_params={'command_wait_limit_s': 1.0})
    with Stack(config) as stack:
        acknowledged: list = []
        stack.node.create_subscription(Header, topic('recorded').name, acknowledged.append,
                                       qos_profile(topic('recorded').qos))
        stack.start()
        monitor = stack.monitor
        # stopped once it has vouched for a file holding the plant's records too (a loaded
        # machine can take seconds over its first bundles: until it acknowledges, the plant
        # counts it from the step at which it appeared; and an acknowledgement made before the
        # plant's first bundle is written vouches for the profile's topics only, a start-up gap
        # named in issue 31's note)
        seen: list[int] = []  # acknowledgements counted when the plant's topics were in

        def vouched() -> bool:
            if not seen and 'recording /train/state [' in stack.log_tail('recorder', 400):
                seen.append(len(acknowledged))
            return (monitor.last_stamp_ns > 2_000_000_000 and bool(seen)
                    and len(acknowledged) > seen[0])
        assert stack.spin_until(vouched, 120.0), stack.log_tail('recorder')
        recorder = stack.processes['recorder']
        recorder.send_signal(signal.SIGSTOP)
        try:
            stack.spin_until(lambda: False, 3.0)
            held_at = monitor.last_stamp_ns
            stack.spin_until(lambda: False, 1.0)
            assert monitor.last_stamp_ns == held_at, (
                f'the loop went on without the recorder: {held_at} ns, then '
                f"{monitor.last_stamp_ns} ns\n{stack.log_tail('plant', 400)}\n"
                f"{stack.log_tail('recorder', 400)}")
            assert held_at < 800_000_000_000, f'the run was at its end ({held_at} ns) at the stop'
            log = stack.log_tail('plant', 400)
            shutil.copytree(tmp_path / 'bag', tmp_path / 'copy')
        finally:
            recorder.send_signal(signal.SIGCONT)
        assert stack.spin_until(lambda: monitor.last_stamp_ns > held_at, 30.0), \
            stack.log_tail('plant')
        assert stack.spin_until(lambda: stack.processes['plant'].poll() is not None, 300.0)
        codes = stack.stop()
        final_log = stack.log_tail('plant', 400)
    assert codes['plant'] == 0 and codes['recorder'] == 0, codes
    assert 'for recorder /recorder, whose file holds the step records up to' in log, log
    assert 'the recorders caught up after' in final_log, final_log
    assert 'steps waited' in final_log, final_log
    recorded = sorted({state_stamp(m) for m in read_messages(tmp_path / 'bag',
                                                             ['/train/state'])})
    assert recorded == [k for k, _ in monitor.complete_samples()]  # every step
    recover(tmp_path / 'copy')
    in_file = [state_stamp(m) for m in read_messages(tmp_path / 'copy', ['/train/state'])]
    assert held_at - in_file[-1] <= round(LEAD_S * 1e9), (held_at, in_file[-1])


def test_a_composed_stack_records_every_step_in_its_own_process(tmp_path, domain_id):
    """The three nodes in one process (``ato_stack --record``) with the recorder in it: the
    nodes hand their per-step messages to it directly (nobody subscribes to the step records
    through the middleware) and the bag holds each per-step topic at every step; the bag is
    closed when the process ends."""
    from rclpy.qos import QoSProfile

    states = []
    config = StackConfig(scenario='short_line', domain_id=domain_id, end_time_s=30.0,
                         composed=True, log_dir=tmp_path / 'logs', record_to=tmp_path / 'bag')
    with Stack(config) as stack:
        stack.node.create_subscription(JointTrajectory, '/train/state', states.append,
                                       QoSProfile(depth=1000))
        stack.start()
        assert stack.spin_until(lambda: len(states) > 10, 120.0), stack.log_tail('loop')
        # A participant's node names come in a discovery message of their own, which a loaded
        # machine can deliver after the endpoints (the name then reads _NODE_NAME_UNKNOWN_).
        def named() -> bool:
            found = stack.node.get_publishers_info_by_topic('/ato/step_records')
            return bool(found) and all(i.node_name != '_NODE_NAME_UNKNOWN_' for i in found)
        assert stack.spin_until(named, 60.0), \
            'no publisher of the step records with a known node name within 60 s'
        publishers = stack.node.get_publishers_info_by_topic('/ato/step_records')
        subscribers = stack.node.get_subscriptions_info_by_topic('/ato/step_records')
        assert stack.spin_until(lambda: stack.processes['loop'].poll() is not None, 300.0)
        codes = stack.stop()
        log = stack.log_tail('loop', 200)
    assert codes == {'loop': 0}, codes
    assert [i.node_name for i in publishers] == ['train_plant_node'] and subscribers == []
    assert 'closed ' in log and str(tmp_path / 'bag') in log
    info = bag_info(tmp_path / 'bag')
    stamps = sorted({state_stamp(m) for m in read_messages(tmp_path / 'bag', ['/train/state'])})
    assert stamps == list(range(0, 30_000_000_001, 100_000_000))  # every step
    for topic in ('/clock', '/train/state/measured', '/train/actuators/commanded',
                  '/train/actuators/applied'):
        assert info.topics[topic].message_count >= len(stamps), topic
    for topic in ('/ato/reference', '/ato/distance_to_go', '/ato/permitted_speed',
                  '/ato/command'):
        assert info.topics[topic].message_count >= len(stamps) - 1, topic
    assert {'/diagnostics', '/ato/reference/curve', '/train/identity'} <= set(info.topics)


def test_a_composed_stack_records_the_topics_named_at_the_time_it_keeps(tmp_path, domain_id):
    """``ato_stack --record`` with a list of topics and ``--log-time receipt``, as a user runs
    it: of the loop's per-step messages the recorder writes only the named topics, each message
    once, at the recorder's time, which (``--sim-time``, implied in the composed stack) the
    loop's /clock sets even though /clock is not recorded: each step's state is logged at its
    step. (The nodes need not wait for it: it is built with them, before the first step.)"""
    import yaml

    from ato_ros.middleware import with_middleware_defaults
    from recorder.rosbag2_format import cdr_stamp_ns

    bag, params = tmp_path / 'bag', tmp_path / 'params.yaml'
    common = {'scenario': 'short_line', 'lockstep': True}
    params.write_text(yaml.safe_dump({
        '/**/train_plant_node': {'ros__parameters': {**common, 'end_time_s': 20.0}},
        '/**/profile_node': {'ros__parameters': dict(common)},
        '/**/ato_controller_node': {'ros__parameters': dict(common)}}))
    env = with_middleware_defaults(dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    run = subprocess.run([executable_path('ato_bringup', 'ato_stack'), '--record', '-o',
                          str(bag), '--log-time', 'receipt', '/train/state', '/ato/command',
                          '--ros-args', '--params-file', str(params)],
                         env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    info = bag_info(bag)
    assert set(info.topics) == {'/train/state', '/ato/command'}
    states = list(read_messages(bag, ['/train/state']))
    assert [cdr_stamp_ns(m.data) for m in states] == list(range(0, 20_000_000_001, 100_000_000))
    assert all(m.log_time_ns == cdr_stamp_ns(m.data) for m in states)
    commands = list(read_messages(bag, ['/ato/command']))
    assert info.topics['/ato/command'].message_count == len(commands) >= len(states) - 1
    assert all(m.log_time_ns == cdr_stamp_ns(m.data) for m in commands)


def test_a_composed_stack_stopped_at_any_moment_has_within_the_lead_on_disk(tmp_path,
                                                                          domain_id):
    """Issue 31: the composed stack's recorder writes on the loop's thread and closes a chunk
    every 1.6 s of simulated time: the process stopped mid-run (SIGSTOP: what a SIGKILL would
    leave, copied and recovered) has on disk every step up to at most the lead (``LEAD_S``)
    before the last one it published; let go, it records every step."""
    import shutil

    from ato_ros.step_records import LEAD_S

    config = StackConfig(scenario='short_line', domain_id=domain_id, end_time_s=300.0,
                         composed=True, log_dir=tmp_path / 'logs', record_to=tmp_path / 'bag')
    with Stack(config) as stack:
        stack.start()
        monitor = stack.monitor
        assert stack.spin_until(lambda: monitor.last_stamp_ns > 20_000_000_000, 120.0), \
            stack.log_tail('loop')
        loop = stack.processes['loop']
        loop.send_signal(signal.SIGSTOP)
        try:
            stack.spin_for(1.0)  # what it published before the stop arrives
            held_at = monitor.last_stamp_ns
            shutil.copytree(tmp_path / 'bag', tmp_path / 'copy')
        finally:
            loop.send_signal(signal.SIGCONT)
        assert held_at < 290_000_000_000, f'the run was at its end ({held_at} ns) at the stop'
        assert stack.spin_until(lambda: loop.poll() is not None, 300.0), stack.log_tail('loop')
        codes = stack.stop()
    assert codes == {'loop': 0}, codes
    recover(tmp_path / 'copy')
    in_file = sorted(state_stamp(m) for m in read_messages(tmp_path / 'copy', ['/train/state']))
    assert in_file == list(range(0, in_file[-1] + 1, 100_000_000))  # every step, in order
    assert held_at - in_file[-1] <= round(LEAD_S * 1e9), (held_at, in_file[-1])
    stamps = sorted({state_stamp(m) for m in read_messages(tmp_path / 'bag', ['/train/state'])})
    assert stamps == list(range(0, 300_000_000_001, 100_000_000))


def test_each_loop_node_announces_its_step_records_before_its_per_step_topics(domain_id):
    """The graph shows a process's publishers in the order they were created. A recorder that
    saw a per-step topic (the plant's /train/state) before the same process's step records
    subscribed to the topic itself and missed the steps published before it matched (a make
    test under load lost the first 4 steps that way): every loop node creates its step
    records' publisher before any per-step one."""
    import rclpy

    from ato_common.conventions import STEP_RECORDED
    from ato_controller_node.node import AtoControllerNode
    from ato_ros.messages import topic
    from profile_node.node import ProfileNode
    from train_plant_node.node import TrainPlantNode
    per_step = {'/' + topic(key).name.lstrip('/') for key in STEP_RECORDED}
    rclpy.init(domain_id=domain_id)
    try:
        for node_class in (TrainPlantNode, ProfileNode, AtoControllerNode):
            node = node_class()
            try:
                names = [publisher.topic_name for publisher in node.publishers]
            finally:
                node.destroy_node()
            records = names.index('/' + topic('step_records').name.lstrip('/'))
            first = min(i for i, name in enumerate(names) if name in per_step)
            assert records < first, (node_class.__name__, names)
    finally:
        rclpy.shutdown()


def test_an_ato_node_of_ones_own_is_recorded_beside_the_step_records(tmp_path, domain_id):
    """Issue 32: an ATO node outside the suite publishes ato/command itself, beside the plant
    and the profile, whose per-step topics come in their step records. The recorder records
    its commands from the topic (its publisher publishes no step records), each once, and the
    others from the step records, each once."""
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState

    from ato_common.types import Command
    from ato_ros import wire
    from ato_ros.messages import qos_profile, topic

    config = StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path / 'logs',
                         record_to=tmp_path / 'bag', end_time_s=30.0)
    with Stack(config) as stack:
        commands = stack.node.create_publisher(JointState, topic('command').name,
                                               qos_profile(topic('command').qos))

        def answer(data: bytes) -> None:  # a P law on the speed, answering every step
            state = wire.decode_state(data)
            force = min(max(2e5 * (10.0 - state.speeds[0]), 0.0), 2e5)
            commands.publish(wire.encode_command(Command(state.stamp_ns, ('traction',),
                                                         (force,), 'own_ato')))
        stack.node.create_subscription(JointTrajectory, topic('state_measured').name, answer,
                                       qos_profile(topic('state_measured').qos), raw=True)
        stack.node.create_subscription(JointTrajectory, topic('reference').name,
                                       lambda data: None, QoSProfile(depth=1000), raw=True)
        # the recorder first (as the Stack starts it), and the run once it has subscribed to the
        # node's commands (a recorder records a publisher from when it has discovered it). The
        # Stack's own monitor subscribes to them too: the recorder's log says when it has.
        stack.start_process('recorder', {}, ['-o', str(config.record_to), '--sim-time',
                                             '--background'])
        subscribed = 'recording /ato/command [sensor_msgs/msg/JointState]'
        assert stack.spin_until(lambda: subscribed in stack.log_tail('recorder', 200), 60.0), \
            stack.log_tail('recorder')
        assert stack.spin_until(lambda: commands.get_subscription_count() >= 2, 60.0)
        params = stack.node_params()
        for name in ('profile', 'plant'):
            stack.start_process(name, params[name])
        assert stack.spin_until(lambda: stack.exited('plant'), 300.0), stack.log_tail('plant')
        codes = stack.stop()
        log = stack.log_tail('recorder', 100)
    assert codes['plant'] == 0 and codes['recorder'] == 0, codes
    messages = list(read_messages(tmp_path / 'bag', ['/ato/command', '/train/state']))
    sent = [wire.decode_joint_state(m.data) for m in messages if m.topic == '/ato/command']
    states = [state_stamp(m) for m in messages if m.topic == '/train/state']
    # every step, in order; a step the plant published again while it waited for the node's
    # command (resend_period_s, on a loaded machine) is there twice, one after the other, as
    # a recorder of the topic gets it, and so may be the node's answer to it
    assert states == sorted(states) and len(set(states)) >= 301, len(states)
    assert {law for _, law, *_ in sent} == {'own_ato'}
    stamps = [stamp for stamp, *_ in sent]
    assert len(stamps) - len(set(stamps)) <= len(states) - len(set(states))
    assert set(states) - set(stamps) <= {max(states)}
    assert 'ato/command has a publisher that publishes no step records' not in log  # from start
    assert 'recording /ato/command [sensor_msgs/msg/JointState], logged at its stamp' in log
