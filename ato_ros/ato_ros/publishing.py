"""What the loop nodes publish and whom they wait for: publishes that must not kill a node,
observation topics published only while someone listens, the step records for the recorders and
the recorders' back-pressure, the plant's identity and the wait for late subscribers.
"""
from __future__ import annotations

import contextlib
import math
import time
from collections import Counter
from operator import itemgetter
from typing import Callable, NamedTuple, Protocol

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration as RclpyDuration
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.qos import ReliabilityPolicy
from std_msgs.msg import Header, UInt8MultiArray

from ato_common.conventions import TOPICS
from ato_common.types import nanoseconds, seconds
from ato_ros.messages import qos_profile, topic
from ato_ros.step_records import WALL_PERIOD_S, Acknowledgements, Bundle
from ato_ros.wire import (
    MessageError,
    decode_header,
)


class Publishing:
    """A node's publishes that must not kill it. rclpy raises ``RCLError`` ('Failed to publish:
    cannot publish data') when the middleware refuses a sample, e.g. a reliable keep-all writer
    whose history is full of samples a reader that died (a SIGKILLed recorder) never
    acknowledged, until discovery drops that reader. Such a failure is counted, logged at most
    once a second and kept for the diagnostics; the node goes on (in lockstep the plant re-sends
    the step, so the loop resumes once the middleware accepts samples again)."""

    def __init__(self, node):
        self.node = node
        self.failures = 0
        self.last_failure = ''

    def __call__(self, publisher, msg) -> bool:
        """Publish ``msg``; False if the middleware refused it."""
        try:
            publisher.publish(msg)
            return True
        except rclpy_implementation.RCLError as error:
            self.failures += 1
            self.last_failure = f'{publisher.topic_name}: {str(error).splitlines()[0]}'
            self.node.get_logger().warning(
                f'publish failed on {self.last_failure} ({self.failures} so far); going on',
                throttle_duration_sec=1.0)
            return False

    def values(self) -> dict[str, object]:
        """The diagnostics' keys of the failures."""
        return {'failed_publishes': self.failures,
                'last_failed_publish': self.last_failure or 'none'}


#: how often an observation topic is published to subscribers that only sample it, s of wall
#: time (above the live view's default 20 Hz)
SAMPLED_PERIOD_S = 0.02


def samples_only(profile) -> bool:
    """A subscription that only samples its topic: best effort, which accepts to lose messages
    (the live view's, ``recorder.live.sampling_qos``; rmw reports no history or depth of a
    remote subscriber, so the reliability is what tells). Every reliable subscriber (a
    recorder, ``ros2 topic echo``, a monitor) is given every message."""
    return profile.reliability == ReliabilityPolicy.BEST_EFFORT


#: how often a per-step check of a publisher's subscribers asks the middleware again, s of wall
#: time: the loop asks before every step (several times), a subscriber comes or goes rarely
SUBSCRIBERS_REFRESH_S = 0.01


class SubscriberCount:
    """``publisher.get_subscription_count()``, asked again at most every ``refresh_s`` of
    wall time (``SUBSCRIBERS_REFRESH_S``): a per-step check of who listens need not cross into
    the middleware at every step of a loop that takes a fraction of a millisecond. A subscriber
    that has just matched is seen within ``refresh_s``; the start of a lockstep run waits for
    its observers with the count itself (``first_unmatched``)."""

    def __init__(self, publisher, refresh_s: float = SUBSCRIBERS_REFRESH_S):
        self.publisher, self.refresh_s = publisher, refresh_s
        self.count, self.asked = 0, -math.inf

    def __call__(self) -> int:
        now = time.monotonic()
        if now - self.asked >= self.refresh_s:
            self.count, self.asked = self.publisher.get_subscription_count(), now
        return self.count


class Observation:
    """When to publish an observation topic (``conventions.OBSERVED_STEP``: the truth, the
    actuator forces, the distance to go and the permitted speed), which the loop does not read:
    on a 2-core machine each per-step publish costs about 0.1 ms of CPU in rclpy. ``due()`` is
    False without a subscriber; True at every step while any subscriber wants every message; and
    at most every ``SAMPLED_PERIOD_S`` of wall time while every subscriber only samples
    (:func:`samples_only`: best effort, e.g. a live view). The subscribers' profiles are read
    again only when their number changes."""

    def __init__(self, node, publisher, period_s: float = SAMPLED_PERIOD_S):
        self.node, self.publisher, self.period_s = node, publisher, period_s
        self.subscribers = SubscriberCount(publisher)
        self.count = 0
        self.every_step = True
        self.last_s = -math.inf

    def due(self) -> bool:
        count = self.subscribers()
        if count == 0:
            self.count = 0
            return False
        if count != self.count:
            infos = self.node.get_subscriptions_info_by_topic(self.publisher.topic_name)
            # a subscriber not yet in the graph's view counts as one that wants every message
            self.every_step = len(infos) < count or not all(
                samples_only(i.qos_profile) for i in infos)
            self.count = count
        if self.every_step:
            return True
        now = time.monotonic()
        if now - self.last_s >= self.period_s:
            self.last_s = now
            return True
        return False


#: a loop node about to exit: how long its last step records may take to reach the recorders, s
#: of wall time (a recorder that died never acknowledges them)
RECORDS_DELIVERY_TIMEOUT_S = 2.0


class StepRecordsPublisher:
    """The publisher of a node's step records as the node sees it: the middleware's publisher,
    with an in-process recorder (:meth:`StepRecorder.attach`) counted as one more subscriber, so
    that a node waiting for its recorders (``wait_for_recorders``) starts, and notices one
    going, the same way for both."""

    def __init__(self, publisher, recorder: StepRecorder):
        self.publisher, self.recorder = publisher, recorder
        self.topic_name = publisher.topic_name

    def get_subscription_count(self) -> int:
        return self.publisher.get_subscription_count() + (self.recorder.local is not None)

    def wait_for_all_acked(self, timeout) -> bool:
        return self.publisher.wait_for_all_acked(timeout)


class TopicWrite(NamedTuple):
    """How a recorder in the loop's process writes one topic of the step records."""

    #: the compiled call that adds one message (its bytes, its log time ns), made when the
    #: records are handed on; None: the topic is not written
    write: Callable[[bytes, int], None] | None
    #: called as the message is added, with its stamp: the log time to write it at (the
    #: recorder's time with ``--log-time receipt``; it may also set that time, as /clock
    #: does); None: the stamp itself
    log_time: Callable[[int], int] | None = None


#: a topic the in-process recorder does not write
NOT_WRITTEN = TopicWrite(None)


class LocalRecorder(Protocol):
    """A recorder in the loop's process (the composed stack's, ``recorder.node``), as a
    :class:`StepRecorder` hands it the per-step messages."""

    def log_for(self, topic: str) -> TopicWrite:
        """How a message of ``topic`` is written. Asked once per topic until
        :meth:`StepRecorder.forget`."""

    def wrote(self, counts: dict[str, int], first_ns: int, last_ns: int) -> int:
        """``counts`` messages of each topic were written since the last call, at log times
        ``first_ns`` to ``last_ns``; returns the log time at which to be told again (when the
        recorder's file is due for a flush)."""


#: a TopicWrite's fields as a plain tuple, which every add unpacks (a tuple subclass, such as a
#: NamedTuple, unpacks more slowly)
_How = tuple[Callable[[bytes, int], None] | None, Callable[[int], int] | None]
#: a message that a recorder in the loop's process waits for: its publisher, the write of its
#: topic (``TopicWrite.write``), its bytes or the (encode, arguments) that make them, its log
#: time ns
_Pending = tuple[object, Callable[[bytes, int], None], object, int]
_PUBLISHER, _LOG_TIME = itemgetter(0), itemgetter(3)


class StepRecorder:
    """A loop node's step records (``ato_ros.step_records``): its per-step messages for the
    recorders. Each step the node asks ``begin_step`` (is a recorder there?), ``add``s every
    per-step message it publishes while one is, and calls ``end_step``, which hands on what is
    due; ``close`` hands on what is left and waits until it is delivered (a node about to exit).

    A recorder in another process subscribes to ``step_records``: the messages are bundled
    (``Bundle``) and the bundle published once it is due. A recorder in the same process (the
    composed stack's, ``recorder.node``) is attached instead (:meth:`attach`): each message added
    is kept as it is (a reference to its bytes, no copy), and when the recorder's file is due
    for a flush (:meth:`report`) all of them are written in one go, by the function the
    recorder gave for each topic (the compiled writer's own call), and counted. One go per
    flush period costs the loop less than a call into the writer at every step (its code and
    data are not brought back into the processor's caches at each one: ``make bench``); a
    process killed loses nothing more than before (the writer would have held the same
    messages in its open chunk, closed at the same flush).

    A message that only the recorders ask for and that costs to make (the profile's
    distance to go, the plant's truth) is added with :meth:`add_later`: its bytes are made
    when they are handed on, in the same go."""

    def __init__(self, node, publishing: Publishing):
        spec = TOPICS['step_records']
        publisher = node.create_publisher(UInt8MultiArray, spec.name, qos_profile(spec.qos))
        self.publisher = StepRecordsPublisher(publisher, self)
        self.publishing = publishing
        self.bundle = Bundle()
        self.recorders = SubscriberCount(publisher)
        self.active = False
        self.bundling = False  # a recorder in another process subscribes
        self.names: dict[object, str] = {}  # publisher -> its topic's full name
        self.local: LocalRecorder | None = None
        self.writes: dict[object, _How] = {}  # publisher -> how its topic is written
        # what the in-process recorder has yet to write, in the order added
        self.pending: list[_Pending] = []
        self.report_due_ns = 0
        # A bundle is sent when a step finds it due; one begun at a step after which no step
        # comes (the plant held for a recorder that waits for this node's first bundle, or
        # ticks that stopped) is sent by this timer once it is WALL_PERIOD_S old.
        self.stale_timer = node.create_timer(WALL_PERIOD_S, self.send_stale,
                                             clock=Clock(clock_type=ClockType.STEADY_TIME))

    def send_stale(self) -> None:
        """Send the bundle in the making if no step has sent it within its wall period."""
        if self.bundling and self.bundle.stale():
            self.flush_bundle()

    def attach(self, recorder: LocalRecorder) -> None:
        """An in-process recorder: each message added is written by ``recorder.log_for`` of its
        topic, and what was written is reported with ``recorder.wrote``."""
        self.local = recorder
        self.writes.clear()

    def forget(self) -> None:
        """Write and report what is pending and ask the recorder again how to write each topic
        (what it records changed: it stopped, or a topic is now taken from elsewhere)."""
        self.report()
        self.writes.clear()

    def detach(self) -> None:
        """The in-process recorder stops (its bag about to close, or a write error): what is
        pending written and reported, and nothing more kept for it (the nodes no longer count
        it)."""
        self.report()
        self.local = None
        self.writes.clear()

    def begin_step(self) -> bool:
        """Whether a recorder records, asked when a bundle begins (a recorder that leaves while
        one is under way is sent the rest of it all the same); without one, nothing is kept."""
        if not self.bundle.names:
            self.bundling = self.recorders() > 0
            self.active = self.bundling or self.local is not None
        return self.active

    def add(self, publisher, log_time_ns: int, data: bytes) -> None:
        """A per-step message of ``publisher`` (its bytes as published, not to be changed
        after), logged at ``log_time_ns``; only while ``active``."""
        if self.active:
            if self.bundling:
                self._bundle(publisher, log_time_ns, data)
            if self.local is not None:
                write, log_time = self.writes.get(publisher) or self._write_of(publisher)
                if write is not None:
                    self.pending.append((publisher, write, data, log_time_ns
                                         if log_time is None else log_time(log_time_ns)))
                elif log_time is not None:
                    log_time(log_time_ns)

    def add_later(self, publisher, log_time_ns: int, encode: Callable[..., bytes],
                  *args) -> None:
        """As :meth:`add`, for a message whose bytes are ``encode(*args)``, made only when a
        recorder takes them (at once for one in another process; with the other pending
        messages for the in-process one). ``args`` must not change after the call (tuples,
        frozen records)."""
        if self.active:
            if self.bundling:
                self._bundle(publisher, log_time_ns, encode(*args))
            if self.local is not None:
                write, log_time = self.writes.get(publisher) or self._write_of(publisher)
                if write is not None:
                    self.pending.append((publisher, write, (encode, args), log_time_ns
                                         if log_time is None else log_time(log_time_ns)))
                elif log_time is not None:
                    log_time(log_time_ns)

    def _bundle(self, publisher, log_time_ns: int, data: bytes) -> None:
        name = self.names.get(publisher)
        if name is None:
            name = self.names[publisher] = publisher.topic_name
        self.bundle.add(name, log_time_ns, data)

    def _write_of(self, publisher) -> _How:
        """How the in-process recorder writes the topic of ``publisher`` (asked once)."""
        assert self.local is not None
        name = self.names.get(publisher)
        if name is None:
            name = self.names[publisher] = publisher.topic_name
        write, log_time = self.local.log_for(name)
        how = self.writes[publisher] = (write, log_time)
        return how

    def end_step(self, stamp_ns: int) -> None:
        if self.bundling and self.bundle.due(stamp_ns):
            self.flush_bundle()
        if self.pending and self.pending[-1][3] >= self.report_due_ns:
            self.report()

    def report(self) -> None:
        """Write what is pending for the in-process recorder and tell it what was written."""
        pending = self.pending
        if not pending or self.local is None:
            return
        self.pending = []
        for _, write, data, log_time_ns in pending:
            if data.__class__ is tuple:  # (encode, args): a message made now
                encode, args = data  # type: ignore[misc]
                data = encode(*args)
            write(data, log_time_ns)  # type: ignore[arg-type]
        counts: dict[str, int] = {}
        names = self.names
        for publisher, count in Counter(map(_PUBLISHER, pending)).items():
            name = names[publisher]  # every pending publisher's, since _write_of
            counts[name] = counts.get(name, 0) + count
        self.report_due_ns = self.local.wrote(counts, min(map(_LOG_TIME, pending)),
                                              max(map(_LOG_TIME, pending)))

    def flush_bundle(self) -> None:
        data = self.bundle.take()
        if data is not None:
            self.publishing(self.publisher.publisher, data)

    def flush(self) -> None:
        """Hand on everything kept (the last steps' records)."""
        self.flush_bundle()
        self.report()

    def close(self, timeout_s: float = RECORDS_DELIVERY_TIMEOUT_S) -> bool:
        """Hand on what is left and wait until every recorder in another process has it (False
        if one did not acknowledge within ``timeout_s``)."""
        self.flush()
        return wait_until_delivered([self.publisher.publisher], timeout_s)


#: while ``run_nodes`` builds several nodes for one process: their step recorders, per namespace
_shared_step_recorders: dict[str, StepRecorder] | None = None


@contextlib.contextmanager
def shared_step_recorders(shared: bool):
    """While the nodes of one process are built (``ato_ros.lifecycle.run_nodes``): with
    ``shared``, every node's :func:`step_recorder` of a namespace is the same one."""
    global _shared_step_recorders
    _shared_step_recorders = {} if shared else None
    try:
        yield
    finally:
        _shared_step_recorders = None


def step_recorder(node, publishing: Publishing) -> StepRecorder:
    """The node's :class:`StepRecorder`. Nodes that ``run_nodes`` builds together in one process
    (the composed stack, ``ato_bringup.composed``) share one per namespace: one bundle, one
    publish per period and one take by the recorder instead of one of each per node (the first
    node's publisher carries it).

    A node asks for it before it creates its per-step publishers: the graph announces a
    process's publishers in the order they were created, and a recorder that saw a per-step
    topic of a process before that process's step records would subscribe to the topic itself
    (``recorder.node.RecorderNode.taken_from_records``), missing the steps published before
    its subscription matched."""
    shared = _shared_step_recorders
    if shared is None:
        return StepRecorder(node, publishing)
    recorder = shared.get(node.get_namespace())
    if recorder is None:
        recorder = shared[node.get_namespace()] = StepRecorder(node, publishing)
    return recorder


def local_step_recorder(namespace: str) -> StepRecorder | None:
    """The step recorder that the nodes of namespace ``namespace`` built so far in this process
    share (``run_nodes``, while it builds them), for an in-process recorder to attach to; None
    outside ``shared_step_recorders`` or if no node of the namespace has one."""
    shared = _shared_step_recorders
    return None if shared is None else shared.get(namespace)


#: the name rmw gives a node whose endpoints are known but not yet its participant's node names
UNKNOWN_NODE_NAME = '_NODE_NAME_UNKNOWN_'


def node_full_name(namespace: str, name: str) -> str:
    """A node's fully qualified name, as ``Node.get_fully_qualified_name`` gives it, from the
    namespace and name the graph reports."""
    return namespace.rstrip('/') + '/' + name


class RecorderLead:
    """Back-pressure of the recorders in lockstep (the plant's side). A lockstep loop runs as
    fast as its nodes answer; without this, a recorder starved of CPU falls behind it, and
    what it has not yet written is lost with it on a SIGKILL while what the publishers keep
    for it (reliable, keep all) grows. The suite's recorder acknowledges each namespace's step
    records on ``recorded`` (the stamp up to which they are in its file, its node name:
    ``ato_ros.step_records.Written``); ``holds(stamp_ns)`` says whether the step at
    ``stamp_ns`` must wait: it is more than ``lead_s`` past the oldest acknowledgement of the
    recorders in the graph (the publishers of ``recorded``; one not yet heard from counts as
    having acknowledged the step at which it was first seen). A recorder that acknowledges
    nothing (any other subscriber of the step records, ``ros2 bag record``) holds nothing back;
    one that leaves lets go. The publishers of ``recorded`` are counted at most every
    ``SUBSCRIBERS_REFRESH_S`` of wall time and named again when their number changes.
    ``on_release`` is called when an acknowledgement, or a recorder's leaving, lets a held step
    go; ``check`` (the node's timer, while holding) names the recorders in the graph again. An
    acknowledgement stamped past the latest step asked about is an earlier run's (the
    acknowledgements are latched, and a plant started again finds a running recorder's last
    one): ignored."""

    def __init__(self, node, lead_s: float, on_release: Callable[[], None],
                 refresh_s: float = SUBSCRIBERS_REFRESH_S):
        spec = TOPICS['recorded']
        self.node, self.on_release, self.refresh_s = node, on_release, refresh_s
        self.acknowledgements = Acknowledgements(nanoseconds(lead_s))
        self.held: int | None = None  # the stamp of the step that waits
        self.latest_ns: int | None = None  # the latest step asked about (``holds``)
        self.held_since = 0.0
        self.steps_held = 0  # steps that waited, and for how long in all (s of wall time)
        self.held_s = 0.0
        self.publishers, self.asked = 0, -math.inf
        self.subscription = node.create_subscription(
            Header, spec.name, self.on_acknowledgement, qos_profile(spec.qos), raw=True)

    def on_acknowledgement(self, data: bytes) -> None:
        try:
            stamp_ns, recorder = decode_header(data)
        except MessageError as error:
            self.node.get_logger().warning(
                f'{self.subscription.topic_name}: an acknowledgement that does not read '
                f'({error}): ignored', throttle_duration_sec=1.0)
            return
        if self.latest_ns is None or stamp_ns > self.latest_ns:
            # Later than any step of this run: a recorder's latched acknowledgement of an earlier
            # run (the plant started again beside it), which vouches for nothing of this one.
            self.node.get_logger().info(
                f'{self.subscription.topic_name}: recorder {recorder} acknowledged '
                f'{seconds(stamp_ns):.3f} s, past this run\'s latest step: an earlier run\'s, '
                'ignored', throttle_duration_sec=1.0)
            return
        self.acknowledgements.acknowledged(recorder, stamp_ns)
        self.release_if_free()

    def holds(self, stamp_ns: int, last: bool = False) -> bool:
        """Whether the step at ``stamp_ns`` must wait; ``last``: the run's last step, which
        waits for nothing (the plant ends with it and closes what it publishes)."""
        self.latest_ns = stamp_ns
        if last:
            self.held = None
            return False
        now = time.monotonic()
        if now - self.asked >= self.refresh_s:
            self.asked = now
            count = self.subscription.get_publisher_count()
            if count != self.publishers and self.name_recorders(stamp_ns):
                self.publishers = count  # else named again at the next refresh
        if self.acknowledgements.behind(stamp_ns) is None:
            self.held = None
            return False
        if self.held != stamp_ns:
            self.held, self.held_since = stamp_ns, now
            self.steps_held += 1
        return True

    def name_recorders(self, stamp_ns: int) -> bool:
        """Forget the recorders no longer in the graph; one new to it is taken as having
        acknowledged ``stamp_ns``. False if the graph does not name every one yet: a
        participant's node names come in a discovery message of their own, which a loaded
        machine can deliver well after its endpoints (rmw then names the node
        ``UNKNOWN_NODE_NAME``). Such a publisher is not taken for a recorder of its own, which
        would never acknowledge and so hold the loop (the recorder's acknowledgements carry its
        real name), and nobody is forgotten while one may be any of them."""
        infos = self.node.get_publishers_info_by_topic(self.subscription.topic_name)
        named = all(i.node_name != UNKNOWN_NODE_NAME for i in infos)
        live = {node_full_name(i.node_namespace, i.node_name) for i in infos
                if i.node_name != UNKNOWN_NODE_NAME}
        acknowledgements = self.acknowledgements
        if named:
            acknowledgements.keep(live)
        for recorder in live:
            acknowledgements.appeared(recorder, stamp_ns)
        return named

    def check(self) -> None:
        if self.held is not None:
            self.name_recorders(self.held)
            self.release_if_free()

    def release_if_free(self) -> None:
        if self.held is not None and self.acknowledgements.behind(self.held) is None:
            self.held = None
            self.held_s += time.monotonic() - self.held_since
            self.on_release()

    def waiting(self) -> str:
        """What a held step waits for ('' if none)."""
        held = self.held
        behind = self.acknowledgements.behind(held) if held is not None else None
        if held is None or behind is None:
            return ''
        recorder, stamp_ns = behind
        acknowledgements = self.acknowledgements
        what = (f'whose file holds the step records up to {seconds(stamp_ns):.3f} s'
                if recorder in acknowledgements.heard else
                f'which has acknowledged nothing since it appeared at {seconds(stamp_ns):.3f} s')
        return (f'the step at {seconds(held):.3f} s has waited '
                f'{time.monotonic() - self.held_since:.1f} s of wall time for recorder '
                f'{recorder}, {what} (lead {seconds(acknowledgements.lead_ns):g} s)')


def watch_plant_identity(node, own_identity: str, refusal: str,
                         on_identified: Callable[[], None] | None = None):
    """Subscribe ``node`` to the plant's latched identity (``train/identity``): a plant that
    simulates another scenario than ``own_identity``'s (or an identity that is not one) makes
    the node log ``refusal`` with both scenarios named and stop with exit code 2; the expected
    one sets ``node.identified`` and then calls ``on_identified`` (once). A node that must send
    nothing to a plant it would refuse waits for ``identified``: on a loaded machine the
    plant's first states can be taken before its identity."""
    from std_msgs.msg import String

    from ato_common.identity import identity_mismatch

    def on_identity(msg) -> None:
        try:
            mismatch = identity_mismatch(own_identity, msg.data)
        except ValueError as error:
            mismatch = str(error)
        if mismatch:
            node.get_logger().error(f'{refusal}: {mismatch}')
            node.exit_code = 2
            node.finished = True
        elif not node.finished and not node.identified:
            node.identified = True
            if on_identified is not None:
                on_identified()
    return node.create_subscription(String, topic('identity').name, on_identity,
                                    qos_profile(topic('identity').qos))


def first_unmatched(wanted) -> str:
    """The topic of the first publisher of ``wanted`` ((publisher or None, subscribers it must
    have)) that has fewer subscribers, '' if none: a node's first output waits for every
    observer on each topic it publishes (DDS matches each topic separately)."""
    for publisher, count in wanted:
        if publisher is not None and publisher.get_subscription_count() < count:
            return publisher.topic_name
    return ''


def wait_until_delivered(publishers, timeout_s: float) -> bool:
    """Wait until every reliable subscriber matched to ``publishers`` has acknowledged all they
    sent (a node about to exit: its last messages must not be lost with it); False if some were
    not acknowledged within ``timeout_s`` in all (a subscriber that died)."""
    deadline = time.monotonic() + timeout_s
    delivered = True
    for publisher in publishers:
        left = max(0.0, deadline - time.monotonic())
        delivered &= publisher.wait_for_all_acked(RclpyDuration(seconds=left))
    return delivered
