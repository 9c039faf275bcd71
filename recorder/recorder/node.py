"""recorder: record topics of the running graph to an MCAP bag (rosbag2 conventions).

    ros2 run recorder recorder -o runs/my_run                 # every topic, new ones too
    ros2 run recorder recorder -o runs/my_run /train/state /ato/command

Messages are written as the raw CDR bytes received (no deserialise/serialise), by the Foxglove
SDK's compiled MCAP writer (``recorder.bag``). Log time (``--log-time``): by default ``stamp``,
the suite's stamped topics (those of :data:`ato_common.conventions.TOPICS` whose message starts
with a header stamp or a time, /clock included) are logged at their own stamp, so a recording is
the same however late the recorder received them; every other topic at the recorder's ROS time
on receipt (simulated time with ``--ros-args -p use_sim_time:=true``, or ``--sim-time``).
``receipt`` logs every topic on receipt, as rosbag2 does. ``--sim-time`` takes the recorder's
time from the ``/clock`` messages it records (the simulated time of the last one, 0 before the
first), as ``use_sim_time`` would but without rclpy's second, deserialising subscription to
``/clock`` (a lockstep run publishes one every step); ``/clock`` is then always subscribed,
recorded only if asked for.

The recorder takes its messages itself: its subscriptions sit on a node of their own that no
executor spins (``<name>_subscriptions``), and every ``--take-period`` of wall time (0.05 s) it
takes whatever each one holds (``take_message``, as bytes) and writes them in the order they
were received. An executor would wake once per message; taking in batches costs a fraction of
that, which matters because the recorder shares the machine with the loop it records. A message
is on disk at most a take period plus a flush period after it was received; SIGINT and SIGTERM
take what is left before closing.

The loop nodes' step records (``ato_ros.step_records``) carry their per-step topics: a per-step
topic of a namespace whose nodes publish step records is taken from them when every publisher
of the topic is in a process that publishes the namespace's step records (DDS participants),
else (an ATO node of your own publishing ``ato/command``) it is subscribed to like any other
topic and its entries in the step records are left out, so each message is recorded once. The
step records are taken by the executor as they come: once what is written of a namespace's
records has moved on by ``ACK_PERIOD_S`` of their stamps, the file is flushed and the stamp
acknowledged on ``recorded`` in that namespace, and in lockstep the plant waits for that
acknowledgement when it is more than its ``recorder_lead_s`` ahead (back-pressure:
``ato_ros.publishing.RecorderLead``). ``--background`` runs the recorder at the lowest CPU
priority, on the CPU the loop leaves (what ``run_scenario`` does in lockstep).

In the composed stack (``ato_stack --record FOLDER``, ``ato_bringup.composed``) the recorder is
a node of the loop's process: the messages of the step records of its namespace are kept by
the loop nodes that add them, without the middleware, and written once per flush period in
one go (``ato_ros.publishing.StepRecorder.attach``, ``RecorderNode.log_for``), on the loop's
thread, by the compiled writer (which holds Python's lock while it writes and compresses, so a
thread of its own could not run beside the loop: it would only add the hand-offs). Its chunks are
flushed every ``IN_PROCESS_FLUSH_PERIOD_LOG_S`` of log time unless ``--flush-period-log`` says
otherwise: a killed process loses at most the plant's lead of the separate processes
(``LEAD_S``), with no acknowledgement.

SIGINT and SIGTERM close the file properly; a SIGKILL loses at most the last take and flush
periods: chunks are flushed every ``--flush-period`` of wall time (0.5 s) and every
``--flush-period-log`` of log time (``RECORDER_FLUSH_PERIOD_LOG_S``, simulated time in a
lockstep run), whichever comes first, and before each acknowledgement that no flush since has
covered (in lockstep, what the plant's lead bounds: 1.7 s of simulated time by default);
``ros2 run recorder recover <bag>`` makes a valid bag of the rest.
"""

from __future__ import annotations

import argparse
import os
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import Header
from std_msgs.msg import UInt8MultiArray as STEP_RECORDS_MSG

from ato_common.conventions import TOPICS
from ato_common.validation import ConfigError
from ato_ros.lifecycle import RunNodeHooks, freeze_startup_objects, run_node
from ato_ros.messages import qos_profile
from ato_ros.publishing import NOT_WRITTEN, StepRecorder, TopicWrite, local_step_recorder
from ato_ros.step_records import (
    LEAD_S,
    Written,
    namespace_of,
    read_bundle,
    step_recorded,
)
from ato_ros.wire import MessageError, encode_header
from recorder.bag import (
    COMPRESSIONS,
    DEFAULT_COMPRESSION,
    DEFAULT_FLUSH_PERIOD_S,
    BagError,
    BagWriter,
)
from recorder.ros_io import message_class, offered_profiles, subscription_qos
from recorder.rosbag2_format import cdr_stamp_ns, starts_with_stamp

LOG_TIMES = ('stamp', 'receipt')
#: how often the recorder takes what its subscriptions hold, s of wall time
DEFAULT_TAKE_PERIOD_S = 0.05
#: a recorder in a process of its own closes a chunk at least this often, s of log time: the
#: plant's lead, which bounds what a killed recorder of a lockstep run loses in any case; its
#: acknowledgements flush more often (every ``ACK_PERIOD_S`` of the step records' stamps), and a
#: shorter period would only close chunks that an acknowledgement closes again a moment later
RECORDER_FLUSH_PERIOD_LOG_S = LEAD_S
#: the composed stack's recorder closes a chunk at least this often, s of log time: the loop
#: nodes keep what they add and write it all just before the flush
#: (``ato_ros.publishing.StepRecorder``), so what a killed process loses is what was kept since
#: the last flush, under this and a step: at
#: 10 Hz, at most the plant's lead for a recorder in another process (``LEAD_S``)
IN_PROCESS_FLUSH_PERIOD_LOG_S = round(LEAD_S - 0.1, 9)
#: at most this many messages of one topic per take (the rest at the next)
MAX_TAKES = 10_000
CLOCK = TOPICS['clock'].name
#: how often the recorder asks again who publishes a per-step topic it takes from the step
#: records (a publisher of its own joining mid-run), in discovery periods
RECHECK_DISCOVERIES = 10


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


def is_internal(topic: str, types) -> bool:
    """The step records and the recorders' acknowledgements (``step_records``, ``recorded``, in
    any namespace): how a recording goes, not how the run does."""
    return any(list(types) == [TOPICS[key].type_name] and namespace_of(topic, key) is not None
               for key in ('step_records', 'recorded'))


def participant(info) -> bytes:
    """The DDS participant (one per process's context) of an endpoint the graph reports: the
    first 12 bytes of its GID, the RTPS GUID prefix."""
    return bytes(info.endpoint_gid[:12])


STEP_RECORDS = TOPICS['step_records']
RECORDED = TOPICS['recorded']
#: --background: the recorder's nice value (the lowest CPU priority)
BACKGROUND_NICE = 19


class RecorderNode(RunNodeHooks, Node):
    """The recorder. ``writer``: a :class:`recorder.bag.BagWriter`; ``in_process`` (the
    composed stack): the step records of its own namespace are handed to it in the process."""

    def __init__(self, writer, topics: list[str] | None, discovery_period_s: float,
                 log_time: str = 'stamp', sim_time: bool = False,
                 take_period_s: float = DEFAULT_TAKE_PERIOD_S, step_records: bool = True,
                 in_process: bool = False):
        super().__init__('recorder')
        # The subscriptions' node: never spun, its messages are taken every take period.
        self.taker = Node(f'{self.get_name()}_subscriptions', context=self.context,
                          start_parameter_services=False)
        # topic -> (subscription, handler)
        self.takes: dict[str, tuple[Subscription, Callable[[bytes], None]]] = {}
        self.writer = writer
        self.sim_time = sim_time
        self.sim_now_ns = 0  # --sim-time: the stamp of the last /clock
        self.clock_topic = self.resolve_topic_name(CLOCK)  # /clock as remapped (a namespace)
        if sim_time and self.get_parameter('use_sim_time').value:
            raise ConfigError('--sim-time and use_sim_time both ask for simulated time: give '
                              'one of them')
        self.log_time = log_time
        self.wanted = set(topics) if topics else None
        self.subscribed: dict[str, Subscription | None] = {}  # None: a topic left out
        # ato_ros.step_records: the per-step topics of a namespace whose loop nodes publish
        # step records are taken from those, not subscribed to one by one
        self.step_records = step_records
        self.bundled: set[str] = set()  # namespaces whose step records are subscribed to
        self.written: dict[str, Written] = {}  # namespace -> what is written of its records
        self.acknowledgers: dict[str, Publisher] = {}  # namespace -> its `recorded` publisher
        self.noted_flushes = 0  # the writer's count of flushes when last looked at
        self.step_subscriptions: list[Subscription] = []
        self.direct: set[str] = set()  # per-step topics subscribed to: left out of the records
        self.from_records: set[str] = set()  # per-step topics taken from the step records
        self.discoveries = 0
        self.local_records: StepRecorder | None = None
        self.local_namespace = self.attach_in_process() if in_process else None
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

    # --- which topic is recorded from where -------------------------------------------------
    def discover(self) -> None:
        self.discoveries += 1
        clock = step_recorded(self.clock_topic)
        if self.sim_time and self.clock_topic not in self.subscribed and \
                self.wanted is not None and self.clock_topic not in self.wanted and \
                (clock is None or not self.carries_records(clock[1])):  # else from the records
            # the time only, not recorded
            self._subscribe(self.clock_topic, ClockMsg, qos_profile(TOPICS['clock'].qos),
                            self._on_clock)
        found = self.get_topic_names_and_types()
        # the step records first: a per-step topic they carry is then not subscribed to
        for topic, types in found:
            if topic not in self.subscribed and \
                    (namespace := self.step_records_namespace(topic, types)) is not None:
                self._subscribe_step_records(topic, namespace)
        if self.discoveries % RECHECK_DISCOVERIES == 0:
            self.recheck_from_records()
        for topic, types in found:
            if topic in self.subscribed or is_internal(topic, types) or \
                    (self.wanted is not None and topic not in self.wanted) or \
                    self.taken_from_records(topic):
                continue
            self._subscribe_topic(topic, types)

    def _subscribe_topic(self, topic: str, types) -> None:
        if len(types) != 1:
            self.get_logger().warning(f'{topic} has several types {types}; not recorded')
            self.subscribed[topic] = None
            return
        type_name = types[0]
        try:
            msg_type = message_class(type_name)
        except LookupError as error:
            self.get_logger().warning(f'{topic}: {error}; not recorded')
            self.subscribed[topic] = None
            return
        offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
        if not offered:
            return  # only subscribers so far: wait for a publisher to learn its QoS
        try:
            self.writer.add_topic(topic, type_name, offered_profiles(offered))
        except BagError as error:
            self.get_logger().warning(f'{error}; not recorded')
            self.subscribed[topic] = None
            return
        stamped = logs_at_stamp(topic, type_name, self.log_time)
        recorded = step_recorded(topic)
        if recorded is not None and self.carries_records(recorded[1]):
            self._subscribe_per_step(topic, msg_type, subscription_qos(offered), recorded[1])
        else:
            self._subscribe(topic, msg_type, subscription_qos(offered),
                            self._handler(topic, stamped))
        self.get_logger().info(f'recording {topic} [{type_name}], logged at '
                               f'{"its stamp" if stamped else "receipt"}')

    def _subscribe_per_step(self, topic: str, msg_type, qos, namespace: str) -> None:
        """A per-step topic of a namespace whose step records this recorder takes, with a
        publisher of its own (an ATO node outside the suite on ato/command): its entries in the
        step records are left out, and it is taken as it comes, each message written at its
        stamp and counted in what is written of the namespace (``Written``): the
        acknowledgements, and so the plant's lead, cover it as they cover the step records."""
        subscription = self.create_subscription(
            msg_type, topic, self._per_step_handler(topic, namespace), qos, raw=True)
        self.subscribed[topic] = subscription
        self.step_subscriptions.append(subscription)  # taken at the close too

    def _per_step_handler(self, topic: str, namespace: str) -> Callable[[bytes], None]:
        """What a per-step topic subscribed to beside the step records does with a message:
        written at its stamp, noted in what is written of the namespace, and acknowledged
        when that has moved on (the plant may be waiting for it, with no bundle coming)."""
        self.direct.add(topic)
        if self.local_records is not None:
            self.local_records.forget()  # its entries in the loop's records are left out
        written = self.written.get(namespace)
        handler = self._handler(topic, stamped=True)

        def on_message(data: bytes) -> None:
            handler(data)
            stamp = cdr_stamp_ns(data)
            if written is not None and stamp is not None:
                written.wrote(topic, stamp)
                self.acknowledge(namespace)
        return on_message

    def carries_records(self, namespace: str) -> bool:
        """Whether this recorder takes the step records of ``namespace``."""
        return self.step_records and (namespace in self.bundled
                                      or namespace == self.local_namespace)

    def taken_from_records(self, topic: str) -> bool:
        """Whether the per-step topic ``topic`` is recorded from its namespace's step records:
        every publisher of it is in a process that publishes them (else, or once subscribed to,
        it is subscribed to). Before any publisher is seen, it is left for later."""
        recorded = step_recorded(topic) if self.step_records else None
        if recorded is None or topic in self.direct or not self.carries_records(recorded[1]):
            return False
        if topic in self.from_records:
            return True
        publishers = self.get_publishers_info_by_topic(topic)
        if not publishers:
            return True  # nobody publishes it yet
        records = {participant(i) for i in self.get_publishers_info_by_topic(
            recorded[1].rstrip('/') + '/' + STEP_RECORDS.name)}
        if all(participant(i) in records for i in publishers):
            self.from_records.add(topic)
            return True
        return False

    def recheck_from_records(self) -> None:
        """A publisher of a per-step topic that joined later, outside the processes whose step
        records carry it: from now on the topic is subscribed to."""
        for topic in list(self.from_records):
            self.from_records.discard(topic)
            if not self.taken_from_records(topic):
                self.get_logger().info(f'{topic} has a publisher that publishes no step '
                                       'records: subscribed to from now on')

    def step_records_namespace(self, topic: str, types) -> str | None:
        """The namespace whose step records ``topic`` is, else None."""
        if list(types) != [STEP_RECORDS.type_name]:
            return None
        return namespace_of(topic, 'step_records')

    def attach_in_process(self) -> str | None:
        """In the composed stack: take the step records of this node's namespace from the loop
        nodes of the process (their shared step recorder), not through the middleware."""
        namespace = self.get_namespace()
        records = local_step_recorder(namespace)
        if records is None:
            raise ConfigError(f'no loop node in namespace {namespace} of this process keeps step '
                              'records: the in-process recorder is built after the loop nodes')
        records.attach(self)
        self.local_records = records
        return namespace

    def _subscribe_step_records(self, topic: str, namespace: str) -> None:
        """Take the per-step topics of ``namespace`` from its step records, ``topic`` (and drop a
        subscription to one of them made before the step records were seen: the loop does not
        start before the recorder has matched the step records, so it has received nothing).
        Without step records (``--no-step-records``) the topic is left alone: nobody bundles
        for this recorder; nor for the recorder's own namespace in the composed stack (handed
        on in the process)."""
        if not self.step_records or namespace == self.local_namespace or (
                self.wanted is not None and not any(
                    (step_recorded(t) or (None, None))[1] == namespace for t in self.wanted)):
            self.subscribed[topic] = None
            return
        offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
        if not offered:
            return  # no publisher yet
        self.bundled.add(namespace)
        written = self.written[namespace] = Written()
        # Taken as they come (an executor's subscription, not the take period's): in lockstep
        # the plant waits for their acknowledgement (ato_ros.publishing.RecorderLead).
        acknowledgements = self.acknowledgers[namespace] = self.create_publisher(
            Header, namespace.rstrip('/') + '/' + RECORDED.name, qos_profile(RECORDED.qos))
        for other in list(self.takes):
            recorded = step_recorded(other)
            if recorded is None or recorded[1] != namespace:
                continue
            subscription, _ = self.takes[other]
            if self.taken_from_records(other):
                del self.takes[other], self.subscribed[other]
                self.taker.destroy_subscription(subscription)
            else:
                # a publisher of its own (an ATO node outside the suite): the subscription is
                # kept, or what it published before the new one matched would be lost
                self.takes[other] = (subscription, self._per_step_handler(other, namespace))

        def on_records(data: bytes) -> None:
            self._on_step_records(data, written, topic, namespace)
        records = self.create_subscription(STEP_RECORDS_MSG, topic, on_records,
                                           subscription_qos(offered), raw=True)
        self.step_subscriptions.append(records)
        self.subscribed[topic] = records
        self.get_logger().info(f'recording the per-step topics of {namespace} from its step '
                               f'records ({topic}), each logged at its step, acknowledged on '
                               f'{acknowledgements.topic_name}')

    # --- the step records -----------------------------------------------------------------
    def _on_step_records(self, data: bytes, written: Written, topic: str,
                         namespace: str) -> None:
        """Every message of a bundle (of step records ``topic`` of ``namespace``) under its own
        topic, at the log time the node gave it (``--log-time receipt``: on receipt); then,
        once what is written of the namespace's records has moved on by ``ACK_PERIOD_S``, the
        file flushed and that acknowledged (``recorded``)."""
        if self.finished:
            return
        try:
            names, entries = read_bundle(data)
        except MessageError as error:
            self.get_logger().warning(f'step records not read: {error}',
                                      throttle_duration_sec=1.0)
            return
        if self.plain(names):
            # the common case: no Python object per message beyond the bundle's entries
            if not self._write_bundle(names, entries, written):
                return
        elif not self._write_entries(self._recorded_entries(
                [(names[i], log_ns, publish_ns, message)
                 for i, log_ns, publish_ns, message in entries], written)):
            return
        if written.acknowledged is None:  # the first waits for every publisher's records
            written.bundled(names)
            written.publishers = self.count_publishers(topic)
        self.acknowledge(namespace)

    def _write_bundle(self, names: list[str], entries, written: Written) -> bool:
        """A bundle's entries written as they are, each topic's latest stamp noted in
        ``written`` (and ``--sim-time``'s from the last /clock)."""
        try:
            self.writer.write_indexed(names, entries)
        except BagError as error:
            self.stop_on_error(error)
            return False
        self.received += len(entries)
        latest, left = written.latest, set(range(len(names)))
        for index, stamp_ns, *_ in reversed(entries):
            if index in left:
                left.discard(index)
                latest[names[index]] = stamp_ns
                if not left:
                    break
        self.note_flushes()  # a flush closing the write holds the entries just noted
        if self.sim_time and self.clock_topic in names:
            self.sim_now_ns = latest[self.clock_topic]
        return True

    def acknowledge(self, namespace: str) -> None:
        """Once what is written of ``namespace``'s step records has moved on by
        ``ACK_PERIOD_S`` (``Written.acknowledgement``): the file flushed, and that stamp
        acknowledged on ``recorded`` in the namespace."""
        written = self.written.get(namespace)
        stamp_ns = written.acknowledgement() if written is not None else None
        if written is not None and stamp_ns is not None:
            if written.needs_flush(stamp_ns):
                self.flush()
            if not self.finished:  # a write error stops the recording: nothing to vouch for
                self.acknowledgers[namespace].publish(encode_header(stamp_ns, self.name))

    def plain(self, topics) -> bool:
        """Whether every entry of step records of ``topics`` is written as it is: every topic
        recorded (and known to the bag), none subscribed to, each at its stamp."""
        return self.wanted is None and not self.direct and self.log_time == 'stamp' and \
            self.writer.topics.keys() >= set(topics)

    def _recorded_entries(self, entries, written: Written | None = None
                          ) -> list[tuple[str, int, bytes]]:
        """The entries of step records (topic, stamp, [publish time,] bytes) this recorder
        writes, as (topic, log time, bytes): those of the topics it records and does not
        subscribe to, each noted in ``written``; /clock read for ``--sim-time``."""
        topics, by_stamp, direct = self.writer.topics, self.log_time == 'stamp', self.direct
        messages = []
        for topic, stamp_ns, *_, message in entries:
            if topic == self.clock_topic and self.sim_time:
                self._on_clock(message)  # the recorder's time, /clock recorded or not
            if (self.wanted is not None and topic not in self.wanted) or topic in direct:
                continue
            if topic not in topics and not self._add_recorded_topic(topic):
                continue
            messages.append((topic, stamp_ns if by_stamp else self.now_ns(), message))
            if written is not None:
                written.wrote(topic, stamp_ns)
        return messages

    def _write_entries(self, messages) -> bool:
        try:
            self.writer.write_many(messages)
        except BagError as error:
            self.stop_on_error(error)
            return False
        self.received += len(messages)
        self.note_flushes()
        return True

    # --- the step records of the loop nodes of this process (ato_ros.publishing.LocalRecorder)
    def log_for(self, topic: str) -> TopicWrite:
        """How a per-step message of ``topic`` that a loop node of this process adds to its
        step records is written (``ato_ros.publishing.StepRecorder``, on the loop's thread):
        by the compiled writer's own call (no Python object per message), at its stamp, or at
        the recorder's time as it is added with ``--log-time receipt``. /clock also sets the
        recorder's time as it is added (``--sim-time``, implied here), and does only that when
        it is not recorded. Not written: not asked for, subscribed to instead, or the
        recording stopped."""
        if self.finished:
            return NOT_WRITTEN
        sets_time = topic == self.clock_topic and self.sim_time
        recorded = (self.wanted is None or topic in self.wanted) and topic not in self.direct \
            and (topic in self.writer.topics or self._add_recorded_topic(topic))
        write = None
        if recorded:
            try:
                write = self.writer.log_function(topic)
            except BagError as error:
                self.stop_on_error(error)
                return NOT_WRITTEN
        at_receipt = recorded and self.log_time != 'stamp'
        if not (sets_time or at_receipt):
            return TopicWrite(write)
        now_ns = self.now_ns

        def log_time(stamp_ns: int) -> int:
            if sets_time:
                self.sim_now_ns = stamp_ns
            return now_ns() if at_receipt else stamp_ns
        return TopicWrite(write, log_time)

    def wrote(self, counts: dict[str, int], first_ns: int, last_ns: int) -> int:
        """What ``log_for``'s writes added since the last call: counted, and the file flushed
        when its flush period has passed; the log time of the next flush."""
        written = {topic: n for topic, n in counts.items() if topic in self.writer.topics}
        self.received += sum(written.values())
        try:
            due_ns = self.writer.wrote(written, first_ns, last_ns)
        except BagError as error:
            self.stop_on_error(error)
            return 0
        self.note_flushes()
        return due_ns

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

    # --- subscriptions taken every take period ----------------------------------------------
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
        taken: list[tuple[int, int, Callable[[bytes], None], bytes]] = []
        for subscription, handler in self.takes.values():
            with subscription.handle:
                for _ in range(MAX_TAKES):
                    message = subscription.handle.take_message(subscription.msg_type, True)
                    if message is None:
                        break
                    taken.append((message[1].get('received_timestamp') or 0, len(taken),
                                  handler, message[0]))
        taken.sort(key=lambda item: item[:2])
        for _, _, handler, data in taken:
            handler(data)

    def take_step_records(self) -> None:
        """The step records delivered but not yet handed to the executor's callbacks."""
        for subscription in self.step_subscriptions:
            with subscription.handle:
                for _ in range(MAX_TAKES):
                    message = subscription.handle.take_message(subscription.msg_type, True)
                    if message is None:
                        break
                    subscription.callback(message[0])

    def _handler(self, topic: str, stamped: bool) -> Callable[[bytes], None]:
        write = self.writer.write
        is_clock = topic == self.clock_topic

        def on_message(data: bytes) -> None:
            if self.finished:
                return
            if is_clock and self.sim_time:
                self._on_clock(data)
            log_time_ns = cdr_stamp_ns(data) if stamped else None
            if log_time_ns is None:
                log_time_ns = self.now_ns()
            try:
                write(topic, log_time_ns, data)
            except BagError as error:
                self.stop_on_error(error)
                return
            self.received += 1
            self.note_flushes()
        return on_message

    # --- the end --------------------------------------------------------------------------
    def flush(self) -> None:
        if self.local_records is not None:
            self.local_records.report()  # what the loop nodes wrote, counted before the flush
        try:
            self.writer.flush()
        except BagError as error:
            self.stop_on_error(error)
            return
        self.note_flushes()

    def note_flushes(self) -> None:
        """After a write or a flush: if the file was flushed since last asked (a bag writer
        closes its chunk every flush period, within a write), everything written so far is
        on disk, and an acknowledgement of it needs no flush of its own."""
        flushes = self.writer.flushes
        if flushes != self.noted_flushes:
            self.noted_flushes = flushes
            for written in self.written.values():
                written.flushed()

    def stop_on_error(self, error: BagError) -> None:
        """A write error (a full disk): say what and where, stop, exit non-zero."""
        self.get_logger().error(str(error))
        self.finished = True
        self.exit_code = 1
        if self.local_records is not None:
            self.local_records.detach()  # the loop nodes write nothing more

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
        if self.local_records is not None:
            self.local_records.detach()  # what they wrote counted; nothing more written
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


def parse_args(argv: list[str], prog: str = 'recorder') -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('topics', nargs='*', help='topics to record (default: all)')
    parser.add_argument('-o', '--output', type=Path, default=None,
                        help='bag folder to create (default: runs/rec-<time>)')
    parser.add_argument('--compression', default=DEFAULT_COMPRESSION, choices=tuple(COMPRESSIONS),
                        help="the chunks' compression (default: none, as rosbag2 Jazzy's MCAP "
                             'plugin writes them unless told otherwise)')
    parser.add_argument('--flush-period', type=float, default=DEFAULT_FLUSH_PERIOD_S,
                        help='close a chunk at least this often, s of wall time (what a '
                             'SIGKILL can lose)')
    parser.add_argument('--flush-period-log', type=float, default=None,
                        help='close a chunk at least this often, s of log time (simulated '
                             f'time with use_sim_time; default {RECORDER_FLUSH_PERIOD_LOG_S:g}, '
                             f'{IN_PROCESS_FLUSH_PERIOD_LOG_S:g} in the composed stack)')
    parser.add_argument('--log-time', choices=LOG_TIMES, default='stamp',
                        help="stamp: the suite's stamped topics at their stamp, others on "
                             'receipt (default); receipt: every topic on receipt')
    parser.add_argument('--take-period', type=float, default=DEFAULT_TAKE_PERIOD_S,
                        help='take what the subscriptions hold this often, s of wall time')
    parser.add_argument('--sim-time', action='store_true',
                        help='the time of unstamped messages: the simulated time of the last '
                             '/clock (as use_sim_time, without its second /clock subscription)')
    parser.add_argument('--custom-data', action='append', default=[], metavar='KEY=VALUE',
                        help="a string pair for metadata.yaml's custom_data (repeatable; the "
                             'recorder adds log_time and recorded_utc, when it started)')
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


def bag_writer(options: argparse.Namespace,
               flush_period_log_s: float = RECORDER_FLUSH_PERIOD_LOG_S) -> BagWriter:
    """The bag the options ask for (``flush_period_log_s`` unless they give
    ``--flush-period-log``); BagError or ValueError naming what is wrong."""
    output = options.output or Path('runs') / datetime.now().strftime('rec-%Y%m%d-%H%M%S')
    custom_data = {'log_time': options.log_time,
                   'recorded_utc': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M:%S UTC')}
    for pair in options.custom_data:
        key, sep, value = pair.partition('=')
        if not sep or not key:
            raise ValueError(f'--custom-data {pair!r} is not KEY=VALUE')
        custom_data[key] = value
    if not (0.0 < options.take_period <= 1.0):
        raise ValueError(f'--take-period {options.take_period:g}: must be over 0 and at most '
                         '1 s')
    return BagWriter(output, options.compression, flush_period_s=options.flush_period,
                     flush_period_log_s=(flush_period_log_s if options.flush_period_log is None
                                         else options.flush_period_log),
                     custom_data=custom_data)


class InProcessRecorder:
    """The composed stack's recorder (``ato_stack --record``), to be built after the loop nodes
    of the process: the recorder's own options (``argv``, as ``recorder`` takes them;
    ``--sim-time`` implied), its bag written on the loop's thread (the module's docstring says
    why), flushed every ``IN_PROCESS_FLUSH_PERIOD_LOG_S`` of log time unless the options say
    otherwise. ConfigError names a wrong option. Calling it builds the node; ``release`` closes
    the bag of a node never built."""

    def __init__(self, argv: list[str]):
        try:
            self.options = parse_args(argv, prog='ato_stack --record')
            self.writer = bag_writer(self.options, IN_PROCESS_FLUSH_PERIOD_LOG_S)
        except (ValueError, BagError) as error:
            raise ConfigError(str(error)) from None
        except SystemExit:
            raise ConfigError(f"the recorder's options {' '.join(argv)} do not parse") from None
        self.node: RecorderNode | None = None

    def __call__(self) -> RecorderNode:
        o = self.options
        self.node = RecorderNode(self.writer, o.topics, o.discovery_period, o.log_time, True,
                                 o.take_period, o.step_records, in_process=True)
        return self.node

    def release(self) -> None:
        if self.node is None and not self.writer.closed:
            try:
                self.writer.close()
            except BagError as error:
                print(f'error: {error}', file=sys.stderr)


def main(args=None) -> int:
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    options = parse_args(argv)
    if options.background:
        os.setpriority(os.PRIO_PROCESS, 0, BACKGROUND_NICE)  # before any thread is started
    try:
        writer = bag_writer(options)
    except (ValueError, BagError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    try:
        return run_node(lambda: RecorderNode(writer, options.topics, options.discovery_period,
                                             options.log_time, options.sim_time,
                                             options.take_period, options.step_records), args)
    finally:
        if not writer.closed:  # the node never came up
            try:
                writer.close()
            except BagError as error:
                print(f'error: {error}', file=sys.stderr)


if __name__ == '__main__':
    raise SystemExit(main())
