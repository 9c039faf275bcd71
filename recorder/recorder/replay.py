"""replay: publish a recording's topics with their original timing.

    ros2 run recorder replay runs/my_run --rate 10 --start-offset 30 --topics /train/state
    ros2 run recorder replay runs/my_run --loop --ros-args -r /train/state:=/replayed/state

Messages go out as the recorded bytes, each topic with the QoS its publishers offered (a latched
topic is replayed latched, a reliable one reliable), read from the recording's offered QoS in
either rosbag2 format: version 9 (named policies, Jazzy) or 8 (numbers). SIGINT and SIGTERM stop
the replay with exit 0. ``/clock`` is replayed as recorded, so nodes with use_sim_time follow
the recording; a recording without ``/clock`` gets one synthesised from the log times
(``--no-clock`` turns both off). /clock is replayed whatever ``--topics`` selects. Topics are
renamed with the standard ROS remapping (``--ros-args -r from:=to``), which applies to the
replay node's publishers.

SIGINT and SIGTERM are taken over first thing (:func:`main` installs its handlers before it
imports rclpy or opens the bag; this module imports nothing heavy), so a replay stopped at any
moment, still importing or already playing, exits 0 without a traceback; a replay started with
SIGINT ignored (a background job of a shell) is stopped by SIGINT all the same.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

CLOCK_TOPIC = '/clock'
MATCH_SETTLE_S = 0.5


class Stop:
    """SIGINT and SIGTERM, taken from the first line of :func:`main`: ``requested`` once either
    came, and the replay told (``replayer.stopped``)."""

    def __init__(self):
        self.requested = False
        self.replayer = None
        signal.signal(signal.SIGINT, self.on_signal)
        signal.signal(signal.SIGTERM, self.on_signal)

    def on_signal(self, signum, frame) -> None:
        self.requested = True
        if self.replayer is not None:
            self.replayer.stopped = True

    @staticmethod
    def ignore() -> None:
        """From here only the teardown: a second signal must not cut it short."""
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='replay', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path)
    parser.add_argument('--rate', type=float, default=1.0, help='speed factor (2: twice as fast)')
    parser.add_argument('--start-offset', type=float, default=0.0,
                        help='skip this many seconds from the start of the recording')
    parser.add_argument('--loop', action='store_true', help='start again at the end')
    parser.add_argument('--topics', nargs='+', default=None, help='replay only these topics')
    parser.add_argument('--no-clock', action='store_true',
                        help='publish no /clock (by default the recorded one, or one '
                             'synthesised from the log times when the recording has none)')
    parser.add_argument('--wait-for-subscribers', type=int, default=0,
                        help='wait until every replayed topic has this many subscribers')
    options = parser.parse_args(argv)
    if not options.rate > 0.0:
        parser.error(f'--rate must be > 0, got {options.rate}')
    if options.start_offset < 0.0:
        parser.error(f'--start-offset must be >= 0, got {options.start_offset}')
    return options


def node_class():
    """The replay's node class (rclpy imported only once the signals are taken over)."""
    from rclpy.node import Node

    from ato_ros.lifecycle import RunNodeHooks

    class ReplayNode(RunNodeHooks, Node):
        """The replay's node. It plays in :func:`main`'s own loop rather than under run_node,
        but ends like every node of the suite (:func:`ato_ros.lifecycle.tear_down`) and
        declares the same hooks: ``finished`` once the recording has been played,
        ``exit_code`` 2 when it cannot be read; it writes nothing, so ``close_outputs`` is the
        default."""

        def __init__(self):
            super().__init__('replay')
    return ReplayNode


class Replayer:
    def __init__(self, node, options: argparse.Namespace):
        from rosgraph_msgs.msg import Clock

        from recorder.bag import BagError, bag_info
        from recorder.ros_io import message_class, replay_qos
        from recorder.rosbag2_format import FormatError
        self.node = node
        self.options = options
        self.info = bag_info(options.bag)
        wanted = set(options.topics) if options.topics else set(self.info.topics)
        unknown = wanted - set(self.info.topics)
        if unknown:
            raise BagError(f'{options.bag} has no topic {", ".join(sorted(unknown))}; it has '
                           f'{", ".join(sorted(self.info.topics))}')
        recorded_clock = CLOCK_TOPIC in self.info.topics
        if options.no_clock:
            wanted.discard(CLOCK_TOPIC)
        elif recorded_clock:
            wanted.add(CLOCK_TOPIC)  # nodes with use_sim_time follow the recording
        self.topics = sorted(wanted)
        self.publishers = {}
        self.qos = {}
        for name in self.topics:
            topic = self.info.topics[name]
            try:
                msg_class = message_class(topic.type)
            except LookupError as error:
                raise BagError(f'{options.bag}: {name}: {error}') from None
            try:
                qos = replay_qos(topic.offered_qos_profiles)
            except FormatError as error:
                raise BagError(f'{options.bag}: {name}: {error}') from None
            self.qos[name] = qos
            self.publishers[name] = node.create_publisher(msg_class, name, qos)
        self.synthesise_clock = not recorded_clock and not options.no_clock
        self.clock_pub = (node.create_publisher(Clock, CLOCK_TOPIC, replay_qos([]))
                          if self.synthesise_clock else None)
        self.published = 0
        self.stopped = False  # set by SIGINT or SIGTERM

    def play_once(self, executor) -> None:
        from rosgraph_msgs.msg import Clock

        from ato_ros.messages import to_time
        from recorder.bag import read_messages
        start_ns = self.info.start_ns + int(self.options.start_offset * 1e9)
        wall_start = time.monotonic()
        last_clock = -1
        for message in read_messages(self.options.bag, self.topics):
            if self.stopped:
                return
            if message.log_time_ns < start_ns:
                continue
            due = wall_start + (message.log_time_ns - start_ns) / 1e9 / self.options.rate
            while not self.stopped:
                delay = due - time.monotonic()
                if delay <= 0.0:
                    break
                executor.spin_once(timeout_sec=min(delay, 0.05))
            if self.stopped:
                return
            if self.clock_pub is not None and message.log_time_ns > last_clock:
                self.clock_pub.publish(Clock(clock=to_time(message.log_time_ns)))
                last_clock = message.log_time_ns
            self.publishers[message.topic].publish(message.data)
            self.published += 1


def main(args=None) -> int:
    stop = Stop()  # before anything else: a signal from here on ends the replay with 0
    return replay(args, stop)


def replay(args, stop: Stop) -> int:
    from rclpy.utilities import remove_ros_args
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    options = parse_args(argv)
    if stop.requested:
        return 0
    import rclpy
    import rclpy.signals

    from ato_ros.lifecycle import make_executor
    from recorder.bag import BagError
    # Our own handlers stay: rclpy's would shut the context down under the executor (an
    # ExternalShutdownException out of spin_once, exit 1).
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = node_class()()
    executor = make_executor()
    executor.add_node(node)
    try:
        if stop.requested:
            return 0
        replayer = Replayer(node, options)
        stop.replayer = replayer
        replayer.stopped = stop.requested
        node.get_logger().info(f'replaying {len(replayer.topics)} topics of {options.bag}')
        play(replayer, executor, options)
        node.get_logger().info(f'replayed {replayer.published} messages'
                               + (' (stopped on signal)' if replayer.stopped else ''))
        node.finished = True
        return node.exit_code
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        node.exit_code = 2
        return node.exit_code
    finally:
        Stop.ignore()
        from ato_ros.lifecycle import tear_down
        tear_down(executor, node)
        if rclpy.ok():
            rclpy.shutdown()


def play(replayer: Replayer, executor, options: argparse.Namespace) -> None:
    """Wait for the subscribers asked for, play (again with ``--loop``) until the end or a
    signal, and give reliable subscribers a moment to take the last messages."""
    import rclpy
    if options.wait_for_subscribers:
        publishers = list(replayer.publishers.values()) + [
            p for p in (replayer.clock_pub,) if p is not None]
        while rclpy.ok() and not replayer.stopped and any(
                p.get_subscription_count() < options.wait_for_subscribers
                for p in publishers):
            executor.spin_once(timeout_sec=0.05)
        # Matched on the publishers' side; give the subscribers' side the moment it may
        # need to match too, or a reliable volatile subscriber can miss the first messages.
        settle = time.monotonic() + MATCH_SETTLE_S
        while not replayer.stopped and time.monotonic() < settle:
            executor.spin_once(timeout_sec=0.05)
    while not replayer.stopped:
        replayer.play_once(executor)
        if not options.loop:
            break
    # Let reliable subscribers take the last messages before the publishers go away.
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline and not replayer.stopped:
        executor.spin_once(timeout_sec=0.05)


if __name__ == '__main__':
    raise SystemExit(main())
