"""recorder: record topics of the running graph to an MCAP bag (rosbag2 conventions).

    ros2 run recorder recorder -o runs/my_run                 # every topic, new ones too
    ros2 run recorder recorder -o runs/my_run /train/state /ato/command

Messages are written as the raw CDR bytes received (no deserialise/serialise). Log time
(``--log-time``): by default ``stamp``, the suite's stamped topics (those of
:data:`ato_common.conventions.TOPICS` whose message starts with a header stamp or a time, /clock
included) are logged at their own stamp, so a recording is the same however late the recorder
received them; every other topic at the recorder's ROS time on receipt (simulated time with
``--ros-args -p use_sim_time:=true``, or ``--sim-time``). ``receipt`` logs every topic on
receipt, as rosbag2 does. ``--sim-time`` takes the recorder's time from the ``/clock`` messages
it records (the simulated time of the last one, 0 before the first), as ``use_sim_time`` would
but without rclpy's second, deserialising subscription to ``/clock`` (a lockstep run publishes
one every step); ``/clock`` is then always subscribed, recorded only if asked for.
The publish time (``--publish-time``): by default ``source``, the publisher's source timestamp
(wall time) as rosbag2 records it; ``log`` writes the log time instead.

The recorder takes its messages itself: its subscriptions sit on a node of their own that no
executor spins (``<name>_subscriptions``), and every ``--take-period`` of wall time (5 ms) it
takes whatever each one holds (``take_message``, as bytes with the message info, which carries
the source timestamp) and writes them in the order they were received. An executor would wake
once per message and, for the message info, would have to be rclpy's single-threaded one; taking
in batches costs a fraction of that, which matters because the recorder shares the machine with
the loop it records. A message is on disk at most a take period plus a flush period after it was
received; SIGINT and SIGTERM take what is left before closing. The loop nodes' step records
(``ato_ros.step_records``) are taken by the executor as they come: once what is written of a
namespace's records has moved on by ``ACK_PERIOD_S`` of their stamps, the file is flushed and
the stamp acknowledged on ``recorded`` in that namespace, and in lockstep the plant waits for
that acknowledgement when it is more than its ``recorder_lead_s`` ahead (back-pressure:
``ato_ros.publishing.RecorderLead``). ``--background`` runs the recorder at the lowest CPU priority,
on the CPU the loop leaves (what ``run_scenario`` does in lockstep).

SIGINT and SIGTERM close the file properly; a SIGKILL loses at most the last take and flush
periods: chunks are flushed every ``--flush-period`` of wall time (0.5 s) and every
``--flush-period-log`` of log time (0.5 s, simulated time in a lockstep run), whichever comes
first, and before each acknowledgement (in lockstep, what the plant's lead bounds: 0.9 s of
simulated time by default); ``ros2 run recorder recover <bag>`` makes a valid bag of the rest.
"""

from __future__ import annotations

import argparse
import os
import sys
from datetime import datetime
from pathlib import Path

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import Header
from std_msgs.msg import UInt8MultiArray as STEP_RECORDS_MSG

from ato_common.conventions import TOPICS
from ato_common.validation import ConfigError
from ato_ros.lifecycle import RunNodeHooks, freeze_startup_objects, run_node
from ato_ros.messages import qos_profile
from ato_ros.step_records import Written, decode_bundle, namespace_of, step_recorded
from ato_ros.wire import MessageError, encode_header
from recorder.bag import (
    DEFAULT_FLUSH_PERIOD_LOG_S,
    DEFAULT_FLUSH_PERIOD_S,
    BagError,
    BagWriter,
)
from recorder.ros_io import message_class, offered_profiles, subscription_qos
from recorder.rosbag2_format import cdr_stamp_ns, starts_with_stamp

LOG_TIMES = ('stamp', 'receipt')
#: how often the recorder takes what its subscriptions hold, s of wall time
DEFAULT_TAKE_PERIOD_S = 0.005
#: at most this many messages of one topic per take (the rest at the next)
MAX_TAKES = 10_000
CLOCK = TOPICS['clock'].name


def is_suite_topic(topic: str, type_name: str) -> bool:
    """Whether ``topic`` is one of the conventions' topics, in any namespace, with its type."""
    for convention in TOPICS.values():
        name = convention.name
        if type_name != convention.type_name:
            continue
        if topic == name if name.startswith('/') else (
                topic == '/' + name or topic.endswith('/' + name)):
            return True
    return False


def logs_at_stamp(topic: str, type_name: str, log_time: str) -> bool:
    return log_time == 'stamp' and is_suite_topic(topic, type_name) and \
        starts_with_stamp(type_name)


STEP_RECORDS = TOPICS['step_records']
RECORDED = TOPICS['recorded']
#: --background: the recorder's nice value (the lowest CPU priority)
BACKGROUND_NICE = 19


class RecorderNode(RunNodeHooks, Node):
    def __init__(self, writer: BagWriter, topics: list[str] | None, discovery_period_s: float,
                 log_time: str = 'stamp', publish_time: str = 'source', sim_time: bool = False,
                 take_period_s: float = DEFAULT_TAKE_PERIOD_S, step_records: bool = True):
        super().__init__('recorder')
        # The subscriptions' node: never spun, its messages are taken every take period.
        self.taker = Node(f'{self.get_name()}_subscriptions', context=self.context,
                          start_parameter_services=False)
        self.takes: dict[str, tuple[object, object]] = {}  # topic -> (subscription, handler)
        self.writer = writer
        self.sim_time = sim_time
        self.sim_now_ns = 0  # --sim-time: the stamp of the last /clock
        self.clock_topic = self.resolve_topic_name(CLOCK)  # /clock as remapped (a namespace)
        if sim_time and self.get_parameter('use_sim_time').value:
            raise ConfigError('--sim-time and use_sim_time both ask for simulated time: give '
                              'one of them')
        self.log_time = log_time
        self.publish_time = publish_time
        self.wanted = set(topics) if topics else None
        self.subscribed: dict[str, object] = {}
        # ato_ros.step_records: the per-step topics of a namespace whose loop nodes publish
        # step records are taken from those, not subscribed to one by one
        self.step_records = step_records
        self.bundled: set[str] = set()  # namespaces whose step records are subscribed to
        self.written: dict[str, Written] = {}  # namespace -> what is written of its records
        self.step_subscriptions: list = []
        self.name = self.get_fully_qualified_name()
        self.received = 0
        self.finished = False  # run_node stops spinning when True
        self.exit_code = 0
        self.outputs_closed = False
        self.discover()
        # Wall-clock timers: with use_sim_time a ROS-time timer would wait for /clock, which a
        # lockstep plant does not start before the recorder has subscribed.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(discovery_period_s, self.discover, clock=steady)
        self.create_timer(writer.flush_period_s, self.flush, clock=steady)
        self.create_timer(take_period_s, self.take, clock=steady)
        wanted = 'all topics' if self.wanted is None else sorted(self.wanted)
        self.get_logger().info(f'recording {wanted} to {writer.path}')
        freeze_startup_objects()

    def discover(self) -> None:
        clock = step_recorded(self.clock_topic)
        if self.sim_time and self.clock_topic not in self.subscribed and \
                self.wanted is not None and self.clock_topic not in self.wanted and \
                (clock is None or clock[1] not in self.bundled):  # else from the step records
            # the time only, not recorded
            self._subscribe(self.clock_topic, ClockMsg, qos_profile(TOPICS['clock'].qos),
                            lambda data, info: self._on_clock(data))
        found = self.get_topic_names_and_types()
        # the step records first: a per-step topic they carry is then not subscribed to
        for topic, types in found:
            if topic not in self.subscribed and self.is_step_records(topic, types):
                self._subscribe_step_records(topic)
        for topic, types in found:
            if topic in self.subscribed or self.is_step_records(topic, types) or \
                    self.is_acknowledgements(topic, types):
                continue
            recorded = step_recorded(topic) if self.step_records else None
            if recorded is not None and recorded[1] in self.bundled:
                continue  # taken from the step records
            if self.wanted is not None and topic not in self.wanted:
                continue
            if len(types) != 1:
                self.get_logger().warning(f'{topic} has several types {types}; not recorded')
                self.subscribed[topic] = None
                continue
            type_name = types[0]
            try:
                msg_type = message_class(type_name)
            except LookupError as error:
                self.get_logger().warning(f'{topic}: {error}; not recorded')
                self.subscribed[topic] = None
                continue
            offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
            if not offered:
                continue  # only subscribers so far: wait for a publisher to learn its QoS
            try:
                self.writer.add_topic(topic, type_name, offered_profiles(offered))
            except BagError as error:
                self.get_logger().warning(f'{error}; not recorded')
                self.subscribed[topic] = None
                continue
            stamped = logs_at_stamp(topic, type_name, self.log_time)
            self._subscribe(topic, msg_type, subscription_qos(offered),
                            self._handler(topic, stamped))
            self.get_logger().info(f'recording {topic} [{type_name}], logged at '
                                   f'{"its stamp" if stamped else "receipt"}')

    def is_step_records(self, topic: str, types) -> bool:
        return list(types) == [STEP_RECORDS.type_name] and \
            namespace_of(topic, 'step_records') is not None

    def is_acknowledgements(self, topic: str, types) -> bool:
        """The recorders' acknowledgements of step records (``recorded``) say how a recording
        goes, not how the run does: not recorded, as the step records themselves are not."""
        return list(types) == [RECORDED.type_name] and \
            namespace_of(topic, 'recorded') is not None

    def _subscribe_step_records(self, topic: str) -> None:
        """Take the per-step topics of ``topic``'s namespace from its step records (and drop a
        subscription to one of them made before the step records were seen: the loop does not
        start before the recorder has matched the step records, so it has received nothing).
        Without step records (``--no-step-records``) the topic is left alone: nobody bundles
        for this recorder."""
        namespace = namespace_of(topic, 'step_records')
        if not self.step_records or (self.wanted is not None and not any(
                (step_recorded(t) or (None, None))[1] == namespace for t in self.wanted)):
            self.subscribed[topic] = None
            return
        offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
        if not offered:
            return  # no publisher yet
        self.bundled.add(namespace)
        for other in list(self.takes):
            recorded = step_recorded(other)
            if recorded is not None and recorded[1] == namespace:
                subscription, _ = self.takes.pop(other)
                self.taker.destroy_subscription(subscription)
                del self.subscribed[other]
        # Taken as they come (an executor's subscription, not the take period's): in lockstep
        # the plant waits for their acknowledgement (ato_ros.publishing.RecorderLead).
        written = self.written[namespace] = Written()
        acknowledgements = self.create_publisher(
            Header, namespace.rstrip('/') + '/' + RECORDED.name, qos_profile(RECORDED.qos))
        self.step_subscriptions.append(self.create_subscription(
            STEP_RECORDS_MSG, topic,
            lambda data: self._on_step_records(data, written, acknowledgements),
            subscription_qos(offered), raw=True))
        self.subscribed[topic] = self.step_subscriptions[-1]
        self.get_logger().info(f'recording the per-step topics of {namespace} from its step '
                               f'records ({topic}), each logged at its step, acknowledged on '
                               f'{acknowledgements.topic_name}')

    def _on_step_records(self, data: bytes, written: Written, acknowledgements) -> None:
        """Every message of a bundle under its own topic, at the log and publish times the
        node gave it (``--log-time receipt``: on receipt; ``--publish-time log``: the log
        time); then, once what is written of the namespace's records has moved on by
        ``ACK_PERIOD_S``, the file flushed and that acknowledged (``recorded``)."""
        if self.finished:
            return
        try:
            entries = decode_bundle(data)
        except MessageError as error:
            self.get_logger().warning(f'step records not read: {error}',
                                      throttle_duration_sec=1.0)
            return
        source, topics, by_stamp = self.publish_time == 'source', self.writer.topics, \
            self.log_time == 'stamp'
        messages = []
        for topic, stamp_ns, publish_time_ns, message in entries:
            if topic == self.clock_topic and self.sim_time:
                self._on_clock(message)  # the recorder's time, /clock recorded or not
            if self.wanted is not None and topic not in self.wanted:
                continue
            if topic not in topics and not self._add_recorded_topic(topic):
                continue
            messages.append((topic, stamp_ns if by_stamp else self.now_ns(), message,
                             publish_time_ns if source else None))
            written.wrote(topic, stamp_ns)
        try:
            self.writer.write_many(messages)
        except BagError as error:
            self.stop_on_error(error)
            return
        self.received += len(messages)
        stamp_ns = written.acknowledgement()
        if stamp_ns is not None:
            self.flush()
            if not self.finished:  # a write error stops the recording: nothing to vouch for
                acknowledgements.publish(encode_header(stamp_ns, self.name))

    def _add_recorded_topic(self, topic: str) -> bool:
        """A topic first met in the step records: its type from the conventions, its QoS as
        its publishers offer it (the conventions' if the graph does not show them yet)."""
        recorded = step_recorded(topic)
        if recorded is None:
            self.get_logger().warning(f'{topic} in the step records is none of the per-step '
                                      'topics; not recorded', throttle_duration_sec=1.0)
            return False
        spec = TOPICS[recorded[0]]
        offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)] \
            or [qos_profile(spec.qos)]
        try:
            self.writer.add_topic(topic, spec.type_name, offered_profiles(offered))
        except BagError as error:
            self.get_logger().warning(f'{error}; not recorded')
            return False
        self.get_logger().info(f'recording {topic} [{spec.type_name}] from the step records')
        return True

    def _on_clock(self, data: bytes) -> None:
        stamp = cdr_stamp_ns(data)
        if stamp is not None:
            self.sim_now_ns = stamp

    def now_ns(self) -> int:
        """The recorder's time: of the last /clock with ``--sim-time``, else its ROS time."""
        return self.sim_now_ns if self.sim_time else self.get_clock().now().nanoseconds

    def _subscribe(self, topic: str, msg_type, qos, handler) -> None:
        subscription = self.taker.create_subscription(msg_type, topic, lambda data: None, qos,
                                                      raw=True)
        self.subscribed[topic] = subscription
        self.takes[topic] = (subscription, handler)

    def take(self) -> None:
        """Take what every subscription holds and hand it on in the order it was received
        (so that ``--sim-time``'s /clock is read where it came among the others)."""
        if self.finished:
            return
        taken = []
        for subscription, handler in self.takes.values():
            with subscription.handle:
                for _ in range(MAX_TAKES):
                    message = subscription.handle.take_message(subscription.msg_type, True)
                    if message is None:
                        break
                    taken.append((message[1].get('received_timestamp') or 0, len(taken),
                                  handler, message))
        taken.sort(key=lambda item: item[:2])
        for _, _, handler, (data, info) in taken:
            handler(data, info)

    def take_step_records(self) -> None:
        """The step records delivered but not yet handed to the executor's callbacks."""
        for subscription in self.step_subscriptions:
            with subscription.handle:
                for _ in range(MAX_TAKES):
                    message = subscription.handle.take_message(subscription.msg_type, True)
                    if message is None:
                        break
                    subscription.callback(message[0])

    def _handler(self, topic: str, stamped: bool):
        write = self.writer.write
        is_clock = topic == self.clock_topic
        source = self.publish_time == 'source'

        def on_message(data: bytes, info: dict) -> None:
            if self.finished:
                return
            if is_clock and self.sim_time:
                self._on_clock(data)
            log_time_ns = cdr_stamp_ns(data) if stamped else None
            if log_time_ns is None:
                log_time_ns = self.now_ns()
            try:
                write(topic, log_time_ns, data,
                      (info.get('source_timestamp') or None) if source else None)
            except BagError as error:
                self.stop_on_error(error)
                return
            self.received += 1
        return on_message

    def flush(self) -> None:
        try:
            self.writer.flush()
        except BagError as error:
            self.stop_on_error(error)

    def stop_on_error(self, error: BagError) -> None:
        """A write error (a full disk): say what and where, stop, exit non-zero."""
        self.get_logger().error(str(error))
        self.finished = True
        self.exit_code = 1

    def close_outputs(self) -> None:
        """Close the bag (summary, metadata.yaml); run_node calls this before the rclpy teardown,
        and destroy_node does if nobody did."""
        if self.outputs_closed:
            return
        self.outputs_closed = True
        if not self.finished:  # what came before the stop is recorded too
            try:
                self.take_step_records()
                self.take()
            except Exception as error:  # noqa: BLE001 - the bag must be closed all the same
                self.get_logger().error(f'the last messages could not be taken: {error}')
        self.finished = True  # a message still delivered is not written to a closed file
        try:
            info = self.writer.close()
            self.get_logger().info(f'closed {info.path}: {info.message_count} messages on '
                                   f'{len(info.topics)} topics, {info.duration_s:.1f} s')
        except BagError as error:
            self.get_logger().error(str(error))
            self.exit_code = 1

    def destroy_node(self) -> None:
        self.close_outputs()
        self.taker.destroy_node()
        super().destroy_node()


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='recorder', description=__doc__.split('\n\n')[0])
    parser.add_argument('topics', nargs='*', help='topics to record (default: all)')
    parser.add_argument('-o', '--output', type=Path, default=None,
                        help='bag folder to create (default: runs/rec-<time>)')
    parser.add_argument('--compression', default='zstd', choices=('zstd', 'lz4', 'none'))
    parser.add_argument('--flush-period', type=float, default=DEFAULT_FLUSH_PERIOD_S,
                        help='close a chunk at least this often, s of wall time (what a '
                             'SIGKILL can lose)')
    parser.add_argument('--flush-period-log', type=float, default=DEFAULT_FLUSH_PERIOD_LOG_S,
                        help='close a chunk at least this often, s of log time (simulated '
                             'time with use_sim_time)')
    parser.add_argument('--log-time', choices=LOG_TIMES, default='stamp',
                        help="stamp: the suite's stamped topics at their stamp, others on "
                             'receipt (default); receipt: every topic on receipt')
    parser.add_argument('--publish-time', choices=('source', 'log'), default='source',
                        help="source: the publisher's source timestamp, as rosbag2 (default); "
                             'log: the log time')
    parser.add_argument('--take-period', type=float, default=DEFAULT_TAKE_PERIOD_S,
                        help='take what the subscriptions hold this often, s of wall time')
    parser.add_argument('--sim-time', action='store_true',
                        help='the time of unstamped messages: the simulated time of the last '
                             '/clock (as use_sim_time, without its second /clock subscription)')
    parser.add_argument('--custom-data', action='append', default=[], metavar='KEY=VALUE',
                        help="a string pair for metadata.yaml's custom_data (repeatable)")
    parser.add_argument('--no-step-records', dest='step_records', action='store_false',
                        help="subscribe to the suite's per-step topics one by one, as to any "
                             "other, instead of taking them from the loop nodes' step records "
                             '(ato/step_records)')
    parser.add_argument('--background', action='store_true',
                        help=f'run at the lowest CPU priority (nice {BACKGROUND_NICE}): the '
                             'recorder takes only the CPU the loop leaves, and in lockstep the '
                             'plant waits for its acknowledgements when it falls behind '
                             '(recorder_lead_s)')
    parser.add_argument('--discovery-period', type=float, default=0.1,
                        help='how often to look for new topics, s')
    return parser.parse_args(argv)


def main(args=None) -> int:
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    options = parse_args(argv)
    output = options.output or Path('runs') / datetime.now().strftime('rec-%Y%m%d-%H%M%S')
    custom_data = {'log_time': options.log_time}
    for pair in options.custom_data:
        key, sep, value = pair.partition('=')
        if not sep or not key:
            print(f'error: --custom-data {pair!r} is not KEY=VALUE', file=sys.stderr)
            return 2
        custom_data[key] = value
    if not (0.0 < options.take_period <= 1.0):
        print(f'error: --take-period {options.take_period:g}: must be over 0 and at most 1 s',
              file=sys.stderr)
        return 2
    if options.background:
        os.setpriority(os.PRIO_PROCESS, 0, BACKGROUND_NICE)  # before any thread is started
    try:
        writer = BagWriter(output, options.compression, flush_period_s=options.flush_period,
                           flush_period_log_s=options.flush_period_log,
                           custom_data=custom_data)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    try:
        return run_node(lambda: RecorderNode(writer, options.topics, options.discovery_period,
                                             options.log_time, options.publish_time,
                                             options.sim_time, options.take_period,
                                             options.step_records), args)
    finally:
        if not writer.closed:  # the node never came up
            try:
                writer.close()
            except BagError as error:
                print(f'error: {error}', file=sys.stderr)


if __name__ == '__main__':
    raise SystemExit(main())
