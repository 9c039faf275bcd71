"""live: watch a running stack in Foxglove, over the Foxglove WebSocket protocol.

    ros2 run recorder live                          # every topic, on ws://127.0.0.1:8765
    ros2 run recorder live --port 8766 /train/state /ato/reference
    ros2 run recorder live --ros-args -p use_sim_time:=true   # Foxglove's clock = /clock

Open Foxglove (the desktop app or app.foxglove.dev), "Open connection", "Foxglove WebSocket",
``ws://127.0.0.1:8765``. Every topic of the graph (or those named) is offered as a channel with
its ROS 2 message definition (``ros2msg`` schema, CDR messages, as in the suite's MCAP
recordings), so Foxglove decodes and plots them as it does a recording. The step records and the
recorders' acknowledgements (``ato/step_records``, ``ato/recorded``) say how a recording goes,
not how the run does: offered only when named.

The protocol is the Foxglove WebSocket protocol, served by the Foxglove SDK (``foxglove-sdk``):
its subprotocol ``foxglove.sdk.v1``, and ``foxglove.websocket.v1``, its former name, for older
clients (:mod:`recorder.ws_front`); a request for neither is refused with HTTP 400 and a text
saying which to ask for.

The view runs at the lowest CPU priority (nice 19) unless ``--no-background``: it takes only the
CPU the loop and the run's monitor leave, so watching cannot starve them.

Free while nobody watches: the view subscribes to a ROS topic only while a Foxglove client is
subscribed to its channel (a panel shows it), and forwards the raw CDR bytes without decoding
them. Cheap while watched: by default (``--rate 20``) it forwards the latest message of each
watched topic 20 times a second of wall time, taken from a one-message history that the
middleware overwrites in between, so a lockstep run at 100x costs the view 20 takes a second
per topic instead of 1000 (what it skips, a recording keeps). ``--rate 0`` forwards every
message (one rclpy take each, on the loop's CPU).

Messages are logged at their own stamp where the suite's conventions give one (as the
recorder's default ``--log-time stamp``), else at the node's ROS time on receipt; with
``use_sim_time`` the node also sends its ROS time to Foxglove as the server's time.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import threading
from typing import Callable

import foxglove
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.utilities import remove_ros_args

from ato_common.validation import ConfigError
from ato_ros.lifecycle import RunNodeHooks, freeze_startup_objects, run_node
from recorder.definitions import DefinitionNotFound, full_definition
from recorder.node import BACKGROUND_NICE, is_internal, logs_at_stamp
from recorder.ros_io import message_class, subscription_qos
from recorder.rosbag2_format import cdr_stamp_ns
from recorder.ws_front import Front

DEFAULT_PORT = 8765
#: messages forwarded per second and watched topic by default (a panel's refresh rate)
DEFAULT_RATE_HZ = 20.0
# What the node logs once it serves, and how a script finds the port (with --port 0: any free).
SERVING = 'Foxglove WebSocket on ws://{host}:{port}'
SERVING_PATTERN = re.compile(r'Foxglove WebSocket on ws://(\S+?):(\d+)')
# How often the view looks for new topics and for what Foxglove clients have asked for, s.
POLL_PERIOD_S = 0.2


def ros2msg_schema(type_name: str) -> foxglove.Schema:
    """A Foxglove schema for a ROS 2 message type: its full ``.msg`` definition (with every
    nested type, as rosbag2's MCAP storage writes it), encoding ``ros2msg``."""
    return foxglove.Schema(name=type_name, encoding='ros2msg',
                           data=full_definition(type_name).encode())


class Watched(foxglove.ServerListener):
    """Which channels Foxglove clients are subscribed to (the server calls this from its own
    threads; the node reads it from the executor's)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._clients: dict[int, set[int]] = {}  # channel id -> ids of subscribed clients

    def on_subscribe(self, client, channel) -> None:
        with self._lock:
            self._clients.setdefault(channel.id, set()).add(client.id)

    def on_unsubscribe(self, client, channel) -> None:
        with self._lock:
            clients = self._clients.get(channel.id, set())
            clients.discard(client.id)
            if not clients:
                self._clients.pop(channel.id, None)

    def channel_ids(self) -> set[int]:
        with self._lock:
            return set(self._clients)


def sampling_qos(offered: list) -> QoSProfile:
    """A one-message history that the middleware overwrites with each new message: the
    recorder's profile (``subscription_qos``: compatible with every publisher, latched where
    they all latch) with a depth of one, and best effort for a stream, so that no publisher
    waits for the view."""
    qos = subscription_qos(offered)
    qos.history, qos.depth = HistoryPolicy.KEEP_LAST, 1
    if qos.durability != DurabilityPolicy.TRANSIENT_LOCAL:
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    return qos


class LiveViewNode(RunNodeHooks, Node):
    outputs_closed = False

    def __init__(self, topics: list[str] | None, host: str, port: int,
                 rate_hz: float = DEFAULT_RATE_HZ, poll_period_s: float = POLL_PERIOD_S):
        super().__init__('live_view')
        self.rate_hz = rate_hz
        # Sampled subscriptions live on a node that no executor spins: nothing is taken when a
        # message arrives; ``sample`` takes the latest at the view's rate.
        self.sampler = Node('live_view_sampler', context=self.context) if rate_hz else None
        self.wanted = set(topics) if topics else None
        self.watched = Watched()
        self.channels: dict[str, foxglove.Channel] = {}   # topic -> channel
        self.types: dict[str, str] = {}
        self.offered: dict[str, list] = {}
        self.skipped: set[str] = set()
        # topic -> its subscription (on this node, or on the sampler) and what forwards it
        self.subscriptions_by_topic: dict[str, tuple[Subscription, Callable[[bytes], None]]] = {}
        self.forwarded = 0
        self.sim_time = self.get_parameter('use_sim_time').value
        self.server, self.front = self.serve(host, port)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(poll_period_s, self.poll, clock=steady)
        if rate_hz:
            self.create_timer(1.0 / rate_hz, self.sample, clock=steady)
        serving = SERVING.format(host=host, port=self.front.port)
        self.get_logger().info(f'{serving} '
                               f'({"every topic" if self.wanted is None else sorted(self.wanted)})')
        freeze_startup_objects()
        self.poll()

    def serve(self, host: str, port: int):
        """The SDK's server on a loopback port of its own, and the door clients connect to
        (``host``:``port``) in front of it (:mod:`recorder.ws_front`)."""
        try:
            server = foxglove.start_server(
                name='ato live view', host='127.0.0.1', port=0, server_listener=self.watched,
                capabilities=[foxglove.Capability.Time] if self.sim_time else [])
        except Exception as error:  # the SDK's errors carry the reason
            raise ConfigError(f'cannot serve Foxglove: {error}') from None
        try:
            front = Front(host, port, server.port)
        except OSError as error:
            server.stop()
            raise ConfigError(f'cannot serve Foxglove on {host}:{port}: '
                              f'{error.strerror or error}') from None
        return server, front

    def poll(self) -> None:
        """Offer new topics as channels; subscribe to the watched ones, unsubscribe from the
        others; send the ROS time."""
        self.discover()
        watched = self.watched.channel_ids()
        for topic, channel in self.channels.items():
            subscribed = topic in self.subscriptions_by_topic
            if channel.id() in watched and not subscribed:
                msg_type, forward = message_class(self.types[topic]), self._forward(topic)
                if self.sampler is None:  # every message, as it arrives
                    subscription = self.create_subscription(
                        msg_type, topic, forward, subscription_qos(self.offered[topic]), raw=True)
                else:
                    subscription = self.sampler.create_subscription(
                        msg_type, topic, lambda data: None, sampling_qos(self.offered[topic]),
                        raw=True)
                self.subscriptions_by_topic[topic] = subscription, forward
                self.get_logger().info(f'watched: {topic}')
            elif channel.id() not in watched and subscribed:
                removed, _ = self.subscriptions_by_topic.pop(topic)
                (self if self.sampler is None else self.sampler).destroy_subscription(removed)
                self.get_logger().info(f'no longer watched: {topic}')
        if self.sim_time:
            now = self.get_clock().now().nanoseconds
            if now > 0:
                self.server.broadcast_time(now)

    def sample(self) -> None:
        """Forward the latest message of each watched topic, if a new one arrived."""
        for subscription, forward in list(self.subscriptions_by_topic.values()):
            # rclpy has no public take outside an executor; this is the call its executors
            # make for a ready subscription (tests/test_live_view.py exercises it).
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, True)
            if taken is not None:
                forward(taken[0])

    def discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self.channels or topic in self.skipped or (
                    self.wanted is not None and topic not in self.wanted):
                continue
            if self.wanted is None and is_internal(topic, types):
                self.skipped.add(topic)  # how a recording goes: offered only when named
                continue
            offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
            if not offered:
                continue  # subscribers only so far: wait for a publisher to learn its QoS
            if len(types) != 1:
                self._skip(topic, f'has several types {types}')
                continue
            try:
                message_class(types[0])
                schema = ros2msg_schema(types[0])
            except (LookupError, DefinitionNotFound) as error:
                self._skip(topic, str(error))
                continue
            self.types[topic] = types[0]
            self.offered[topic] = offered
            self.channels[topic] = foxglove.Channel(topic, schema=schema,
                                                    message_encoding='cdr')

    def _skip(self, topic: str, reason: str) -> None:
        self.skipped.add(topic)
        self.get_logger().warning(f'{topic}: {reason}; not offered')

    def _forward(self, topic: str) -> Callable[[bytes], None]:
        channel, clock = self.channels[topic], self.get_clock()
        stamped = logs_at_stamp(topic, self.types[topic], 'stamp')

        def on_message(data: bytes) -> None:
            log_time_ns = cdr_stamp_ns(data) if stamped else None
            channel.log(data, log_time=log_time_ns if log_time_ns is not None
                        else clock.now().nanoseconds)
            self.forwarded += 1
        return on_message

    def close_outputs(self) -> None:
        if self.outputs_closed:
            return
        self.outputs_closed = True
        self.front.stop()
        self.server.stop()
        if self.sampler is not None:
            self.sampler.destroy_node()

    def destroy_node(self) -> None:
        self.close_outputs()
        super().destroy_node()


def served_url(log_text: str) -> str | None:
    """The ws:// address a live view's log says it serves on (None before it does)."""
    found = SERVING_PATTERN.search(log_text)
    return f'ws://{found.group(1)}:{found.group(2)}' if found else None


def rate(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a rate in Hz') from None
    if not (value >= 0.0 and value <= 1000.0):
        raise argparse.ArgumentTypeError(f'{text} Hz is not a rate of 0 (every message) to '
                                         '1000 Hz')
    return value


def port_number(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a port number') from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f'{port} is not a port number (0..65535; 0: any free)')
    return port


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='live', description=__doc__.split('\n\n')[0])
    parser.add_argument('topics', nargs='*', help='topics to offer (default: all)')
    parser.add_argument('--host', default='127.0.0.1',
                        help='address to serve on (default: this machine only; 0.0.0.0: every '
                             'interface)')
    parser.add_argument('--port', type=port_number, default=DEFAULT_PORT,
                        help=f'WebSocket port (default {DEFAULT_PORT}, as Foxglove expects)')
    parser.add_argument('--no-background', dest='background', action='store_false',
                        help=f'keep the normal CPU priority (by default nice {BACKGROUND_NICE}: '
                             'the view takes only the CPU the run leaves)')
    parser.add_argument('--rate', type=rate, default=DEFAULT_RATE_HZ,
                        help=f'latest messages forwarded per second and watched topic (default '
                             f'{DEFAULT_RATE_HZ:g}; 0: every message)')
    return parser.parse_args(argv)


def main(args=None) -> int:
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    options = parse_args(argv)
    if options.background:
        os.setpriority(os.PRIO_PROCESS, 0, BACKGROUND_NICE)  # before any thread is started
    foxglove.set_log_level('WARNING')
    return run_node(lambda: LiveViewNode(options.topics, options.host, options.port,
                                         options.rate), args)


if __name__ == '__main__':
    raise SystemExit(main())
