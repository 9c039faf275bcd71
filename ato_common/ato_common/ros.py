"""The rclpy edge of the conventions: QoS profiles, message conversion, node helpers.

Only the node adapters import this module; the cores use :mod:`ato_common.types`.
"""

from __future__ import annotations

import faulthandler
import gc
import math
import os
import signal
import sys
import textwrap
import time
from typing import Callable, Iterable, Sequence

import rclpy
import rclpy.exceptions
import rclpy.signals
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.duration import Duration as RclpyDuration
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, UInt8MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ato_common.conventions import REFERENCE_JOINT, TOPICS, QosSpec, Topic
from ato_common.step_records import Acknowledgements, Bundle
from ato_common.types import NS_PER_S, Command, Reference, TrainState, nanoseconds, seconds
from ato_common.wire import (
    MessageError,
    UnknownEncoding,
    command_from_fields,
    decode_header,
    reference_from_fields,
    state_from_fields,
)

__all__ = ['MessageError']  # re-exported: the nodes catch it from here


def qos_profile(spec: QosSpec) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST if spec.depth else HistoryPolicy.KEEP_ALL,
        depth=spec.depth or 1000,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local
                    else DurabilityPolicy.VOLATILE))


def topic(key: str) -> Topic:
    return TOPICS[key]


def to_time(stamp_ns: int) -> Time:
    return Time(sec=stamp_ns // NS_PER_S, nanosec=stamp_ns % NS_PER_S)


def from_time(stamp: Time) -> int:
    return stamp.sec * NS_PER_S + stamp.nanosec


def to_duration(time_s: float) -> Duration:
    ns = int(round(time_s * NS_PER_S))
    return Duration(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def from_duration(duration: Duration) -> float:
    return duration.sec + duration.nanosec * 1e-9


def state_to_msg(state: TrainState) -> JointTrajectory:
    msg = JointTrajectory()
    msg.header.stamp = to_time(state.stamp_ns)
    msg.joint_names = list(state.car_names)
    point = JointTrajectoryPoint()
    point.positions = list(state.positions)
    point.velocities = list(state.speeds)
    point.accelerations = list(state.accelerations)
    point.effort = list(state.forces)
    msg.points = [point]
    return msg


def _points(msg: JointTrajectory) -> list[tuple]:
    return [(p.positions, p.velocities, p.accelerations, p.effort,
             from_duration(p.time_from_start)) for p in msg.points]


def state_from_msg(msg: JointTrajectory) -> TrainState:
    return state_from_fields(from_time(msg.header.stamp), msg.joint_names, _points(msg))


def reference_to_msg(reference: Reference) -> JointTrajectory:
    msg = JointTrajectory()
    msg.header.stamp = to_time(reference.stamp_ns)
    msg.joint_names = [REFERENCE_JOINT]
    t0 = reference.points[0].time_s
    points = []
    for r in reference.points:
        point = JointTrajectoryPoint()
        point.positions = [r.position]
        point.velocities = [r.speed]
        point.accelerations = [r.acceleration]
        point.effort = [r.jerk]  # the reference's jerk (m/s^3) rides in the effort field
        point.time_from_start = to_duration(r.time_s - t0)
        points.append(point)
    msg.points = points
    return msg


def reference_from_msg(msg: JointTrajectory, time_origin_s: float = 0.0) -> Reference:
    """``time_origin_s`` maps the stamp to the curve's own time (0 in lockstep)."""
    return reference_from_fields(from_time(msg.header.stamp), msg.joint_names, _points(msg),
                                 time_origin_s)


def command_to_msg(command: Command) -> JointState:
    msg = JointState()
    msg.header.stamp = to_time(command.stamp_ns)
    msg.header.frame_id = command.law
    msg.name = list(command.actuator_names)
    msg.effort = list(command.forces)
    return msg


def actuator_forces_to_msg(stamp_ns: int, names: Sequence[str],
                           forces: Sequence[float]) -> JointState:
    """Force per actuated unit (commanded or applied) in effort, N."""
    msg = JointState()
    msg.header.stamp = to_time(stamp_ns)
    msg.name = list(names)
    msg.effort = [float(f) for f in forces]
    return msg


def command_from_msg(msg: JointState, expected_actuators: Sequence[str]) -> Command:
    """Validate a command against the plant's actuators; raise MessageError with the reason."""
    return command_from_fields(from_time(msg.header.stamp), msg.header.frame_id, msg.name,
                               msg.effort, expected_actuators)


def decoded(data: bytes, decode: Callable, msg_type, from_msg: Callable, *args):
    """A message taken raw (``create_subscription(..., raw=True)``), read by ``decode`` (an
    :mod:`ato_common.wire` decoder); bytes in an encoding it does not read are deserialised by
    the middleware's own type support (``msg_type``) and converted by ``from_msg``, so that a
    publisher of any encoding is understood. Raises MessageError naming what is wrong."""
    try:
        return decode(data, *args)
    except UnknownEncoding:
        from rclpy.serialization import deserialize_message
        return from_msg(deserialize_message(data, msg_type), *args)


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      values: dict[str, object]) -> DiagnosticStatus:
    status = DiagnosticStatus()
    status.name = name
    status.hardware_id = hardware_id
    status.level = level
    status.message = message
    status.values = [KeyValue(key=k, value=_format_value(v)) for k, v in values.items()]
    return status


def _format_value(value: object) -> str:
    if isinstance(value, float):
        return f'{value:.9g}'
    return str(value)


def status_name(node, part: str) -> str:
    """The name of a node's diagnostics status: the node's fully qualified name without its
    leading slash, and what the status is about (``train_plant_node: simulation`` in the root
    namespace, ``train1/train_plant_node: simulation`` in ``/train1``), so that the statuses of
    two stacks on the one ``/diagnostics`` are told apart."""
    return f'{node.get_fully_qualified_name().lstrip("/")}: {part}'


def status_in_namespace(name: str, namespace: str) -> str | None:
    """A status ``name`` as its node's own (``train_plant_node: simulation``) if it comes from a
    node of ``namespace`` (``/train1``, ``/`` the root), else None."""
    prefix = namespace.strip('/')
    node_part = name.split(':', 1)[0]
    if not prefix:
        return name if '/' not in node_part else None
    if not name.startswith(prefix + '/'):
        return None
    relative = name[len(prefix) + 1:]
    return relative if '/' not in relative.split(':', 1)[0] else None


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


class StepRecorder:
    """A loop node's step records (``ato_common.step_records``): its per-step messages bundled
    for the recorders on ``step_records``. Each step the node asks ``begin_step`` (is a recorder
    subscribed?), ``add``s every per-step message it publishes while one is, and calls
    ``end_step``, which publishes the bundle once it is due; ``close`` publishes what is left
    and waits until it is delivered (a node about to exit)."""

    def __init__(self, node, publishing: Publishing):
        spec = TOPICS['step_records']
        self.publisher = node.create_publisher(UInt8MultiArray, spec.name, qos_profile(spec.qos))
        self.publishing = publishing
        self.bundle = Bundle()
        self.recorders = SubscriberCount(self.publisher)
        self.active = False
        self.names: dict[object, str] = {}  # publisher -> its topic's full name

    def begin_step(self) -> bool:
        """Whether a recorder subscribes, asked when a bundle begins (a recorder that leaves
        while one is under way is sent the rest of it all the same); without one, nothing is
        kept."""
        if not len(self.bundle):
            self.active = self.recorders() > 0
        return self.active

    def add(self, publisher, log_time_ns: int, data: bytes) -> None:
        """A per-step message of ``publisher`` (its bytes as published), logged at
        ``log_time_ns``; only while ``active``."""
        if self.active:
            name = self.names.get(publisher)
            if name is None:
                name = self.names[publisher] = publisher.topic_name
            self.bundle.add(name, log_time_ns, data)

    def end_step(self, stamp_ns: int) -> None:
        if self.bundle.due(stamp_ns):
            self.flush()

    def flush(self) -> None:
        data = self.bundle.take()
        if data is not None:
            self.publishing(self.publisher, data)

    def close(self, timeout_s: float = RECORDS_DELIVERY_TIMEOUT_S) -> bool:
        """Publish what is left and wait until every recorder has it (False if one did not
        acknowledge within ``timeout_s``)."""
        self.flush()
        return wait_until_delivered([self.publisher], timeout_s)


#: while ``run_nodes`` builds several nodes for one process: their step recorders, per namespace
_shared_step_recorders: dict[str, StepRecorder] | None = None


def step_recorder(node, publishing: Publishing) -> StepRecorder:
    """The node's :class:`StepRecorder`. Nodes that ``run_nodes`` builds together in one process
    (the composed stack, ``ato_bringup.composed``) share one per namespace: one bundle, one
    publish per period and one take by the recorder instead of one of each per node (the first
    node's publisher carries it)."""
    shared = _shared_step_recorders
    if shared is None:
        return StepRecorder(node, publishing)
    recorder = shared.get(node.get_namespace())
    if recorder is None:
        recorder = shared[node.get_namespace()] = StepRecorder(node, publishing)
    return recorder


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
    ``ato_common.step_records.Written``); ``holds(stamp_ns)`` says whether the step at
    ``stamp_ns`` must wait: it is more than ``lead_s`` past the oldest acknowledgement of the
    recorders in the graph (the publishers of ``recorded``; one not yet heard from counts as
    having acknowledged the step at which it was first seen). A recorder that acknowledges
    nothing (any other subscriber of the step records, ``ros2 bag record``) holds nothing back;
    one that leaves lets go. The publishers of ``recorded`` are counted at most every
    ``SUBSCRIBERS_REFRESH_S`` of wall time and named again when their number changes.
    ``on_release`` is called when an acknowledgement, or a recorder's leaving, lets a held step
    go; ``check`` (the node's timer, while holding) names the recorders in the graph again."""

    def __init__(self, node, lead_s: float, on_release: Callable[[], None],
                 refresh_s: float = SUBSCRIBERS_REFRESH_S):
        spec = TOPICS['recorded']
        self.node, self.on_release, self.refresh_s = node, on_release, refresh_s
        self.acknowledgements = Acknowledgements(nanoseconds(lead_s))
        self.held: int | None = None  # the stamp of the step that waits
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
        self.acknowledgements.acknowledged(recorder, stamp_ns)
        self.release_if_free()

    def holds(self, stamp_ns: int) -> bool:
        now = time.monotonic()
        if now - self.asked >= self.refresh_s:
            self.asked = now
            count = self.subscription.get_publisher_count()
            if count != self.publishers:
                self.publishers = count
                self.name_recorders(stamp_ns)
        if self.acknowledgements.behind(stamp_ns) is None:
            self.held = None
            return False
        if self.held != stamp_ns:
            self.held, self.held_since = stamp_ns, now
            self.steps_held += 1
        return True

    def name_recorders(self, stamp_ns: int) -> None:
        """Forget the recorders no longer in the graph; one new to it is taken as having
        acknowledged ``stamp_ns``."""
        live = {node_full_name(i.node_namespace, i.node_name)
                for i in self.node.get_publishers_info_by_topic(self.subscription.topic_name)}
        acknowledgements = self.acknowledgements
        acknowledgements.keep(live)
        for recorder in live:
            acknowledgements.appeared(recorder, stamp_ns)

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
        behind = self.acknowledgements.behind(self.held) if self.held is not None else None
        if behind is None:
            return ''
        recorder, stamp_ns = behind
        return (f'the step at {seconds(self.held):.3f} s has waited '
                f'{time.monotonic() - self.held_since:.1f} s of wall time for recorder '
                f'{recorder}, whose file holds the step records up to {seconds(stamp_ns):.3f} s '
                f'(lead {seconds(self.acknowledgements.lead_ns):g} s)')


def watch_plant_identity(node, own_identity: str, refusal: str):
    """Subscribe ``node`` to the plant's latched identity (``train/identity``): a plant that
    simulates another scenario than ``own_identity``'s (or an identity that is not one) makes
    the node log ``refusal`` with both scenarios named and stop with exit code 2."""
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


def make_executor(context=None):
    """The executor every node of the suite spins: EventsExecutor (about 0.35 ms per
    inter-process round trip against 0.57 ms for SingleThreadedExecutor) unless the environment
    variable ATO_EXECUTOR=single asks for the default one (for comparisons in the benchmark)."""
    if os.environ.get('ATO_EXECUTOR', 'events') != 'single':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:  # pragma: no cover - older rclpy
            pass
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor(context=context)


def freeze_startup_objects() -> None:
    """Call once at the end of a node's start-up (everything built, publishers and subscriptions
    created). A full cyclic-GC collection visits every tracked object, and numba's, scipy's and
    the start-up's own are many: tens of ms, every few thousand control periods of a long run,
    each time a late step. Start-up garbage is collected first; what is left is moved out of
    the collector's sight for good (objects made later are collected as usual)."""
    gc.collect()
    gc.freeze()


# A node asked to stop must end: if tearing down the executor, the node's rcl entities and the
# context takes longer than this (a rare middleware hang), every thread's Python stack is written
# to stderr and the process exits with code 1, instead of waiting for its supervisor's SIGKILL.
TEARDOWN_LIMIT_S = 5.0


class RunNodeHooks:
    """What :func:`run_node` calls on the node it runs, with the defaults of a node that needs
    none of it. Every node class of the suite inherits it before ``rclpy.node.Node``
    (``class PlantNode(RunNodeHooks, Node)``); run_node refuses a node that does not.

    ``finished``
        run_node spins until this becomes True (or rclpy shuts down, or a signal arrives).
        Default False: the node runs until it is stopped.
    ``exit_code``
        the process's exit status, read after the teardown. Default 0.
    ``close_outputs()``
        called once spinning has stopped, before the executor and the node are torn down and
        with no time limit: flush and close what the node writes (the recorder's bag).
        Default: nothing to close.
    """

    finished: bool = False
    exit_code: int = 0

    def close_outputs(self) -> None:
        """Nothing to close by default."""


def tear_down(executor, node: RunNodeHooks | Sequence[RunNodeHooks]) -> None:
    """Shut the executor down (it lets go of every entity while the context is still valid),
    then destroy the node (or each of the nodes), within ``TEARDOWN_LIMIT_S``: past it,
    faulthandler writes every thread's stack to stderr and the process exits with code 1. The
    caller shuts rclpy down."""
    faulthandler.dump_traceback_later(TEARDOWN_LIMIT_S, exit=True)
    executor.shutdown(timeout_sec=TEARDOWN_LIMIT_S)
    for each in (node if isinstance(node, (list, tuple)) else (node,)):
        each.destroy_node()


def help_requested(args=None) -> bool:
    """Whether the command line (without its ``--ros-args`` part) asks for ``-h``/``--help``."""
    from rclpy.utilities import remove_ros_args
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    return '-h' in argv or '--help' in argv


def node_usage(package: str, executable: str, doc: str | None, params: Iterable) -> str:
    """``--help`` of a node: how to start it, the first paragraph of its module docstring and
    every declared parameter (:class:`ato_common.params.Param`) with its type, default, range or
    valid values, whether it may change at run time, and its description."""
    lines = [f'usage: ros2 run {package} {executable} [-h] [--ros-args -p NAME:=VALUE ...]', '']
    summary = (doc or '').strip().split('\n\n')[0]
    lines += [textwrap.fill(' '.join(summary.split()), 100), '', 'parameters:']
    for p in params:
        kind = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}[type(p.default)]
        facts = [kind, f'default {p.default!r}']
        if p.minimum is not None or p.maximum is not None:
            facts.append(f'range [{p.minimum:g}, {p.maximum:g}]')
        if p.choices:
            facts.append('one of: ' + ', '.join(p.choices))
        facts.append('fixed at start-up' if p.read_only else 'may change at run time')
        lines.append(f"  {p.name} ({'; '.join(facts)})")
        lines.append(textwrap.fill(p.description, 100, initial_indent=' ' * 6,
                                   subsequent_indent=' ' * 6))
    return '\n'.join(lines)


def run_node(make_node: Callable[[], RunNodeHooks], args=None,
             usage: Callable[[], str] | None = None) -> int:
    """Entry point body of every node: init, build, spin until shutdown or the node asks to stop
    (``node.finished`` becomes True), clean up. SIGINT and SIGTERM end it cleanly with exit 0
    (or the node's ``exit_code``); a configuration error is printed and gives exit 2 before
    anything is published. The node must declare the hooks (:class:`RunNodeHooks`): any other
    object is a TypeError naming its class.

    Teardown order: the node's own outputs first (``node.close_outputs()``, e.g. the recorder's
    file, with no time limit), then, within ``TEARDOWN_LIMIT_S``, the executor (it lets go of
    every entity while the context is still valid), the node, the context.

    ``usage``: the text ``-h``/``--help`` prints (then the node exits 0 without starting)."""
    return run_nodes((make_node,), args, usage)


def run_nodes(makers: Sequence[Callable[[], RunNodeHooks]], args=None,
              usage: Callable[[], str] | None = None) -> int:
    """:func:`run_node` for several nodes in one process on one executor (the composed stack,
    ``ato_bringup.composed``): built in the order given, spun together until any of them is
    finished; each one's outputs are closed in that order; the exit code is the first non-zero
    ``exit_code`` among them (0 if none)."""
    from ato_common.validation import ConfigError
    if usage is not None and help_requested(args):
        print(usage())
        return 0
    faulthandler.enable()  # a fatal signal or SIGABRT writes every thread's stack to stderr
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop = {'requested': False}

    def on_signal(signum, frame):
        stop['requested'] = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    global _shared_step_recorders
    try:
        nodes = []
        if len(makers) > 1:
            _shared_step_recorders = {}  # step_recorder: one bundle for the nodes built here
        for make_node in makers:
            try:
                node = make_node()
            except ConfigError as error:
                print(f'error: {error}', file=sys.stderr)
                return 2
            except (rclpy.exceptions.InvalidParameterValueException,
                    rclpy.exceptions.InvalidParameterTypeException) as error:
                # a --ros-args or --params-file value the parameter's descriptor refuses
                print(f'error: {error}', file=sys.stderr)
                return 2
            if not isinstance(node, RunNodeHooks):  # rclpy.shutdown below lets go of it
                raise TypeError(f'{type(node).__module__}.{type(node).__qualname__} does not '
                                'declare the hooks run_node calls (finished, exit_code, '
                                'close_outputs): inherit ato_common.ros.RunNodeHooks')
            nodes.append(node)
        _shared_step_recorders = None
        executor = make_executor()
        for node in nodes:
            executor.add_node(node)
        while rclpy.ok() and not stop['requested'] and not any(n.finished for n in nodes):
            executor.spin_once(timeout_sec=0.05)
        for node in nodes:
            node.get_logger().info('shutting down' + (' on signal' if stop['requested'] else ''))
        for node in nodes:
            node.close_outputs()
        tear_down(executor, nodes)
        return next((int(n.exit_code) for n in nodes if n.exit_code), 0)
    finally:
        _shared_step_recorders = None
        if rclpy.ok():
            rclpy.shutdown()
        # From here the process only tears down. A second SIGINT, as Ctrl-C in a launch sends one
        # to the group and launch forwards another, must not kill it half-way with the
        # interpreter's default handler.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
