"""recorder: record topics of the running graph to an MCAP bag (rosbag2 conventions).

    ros2 run recorder recorder -o runs/my_run                 # every topic, new ones too
    ros2 run recorder recorder -o runs/my_run /train/state /ato/command

Messages are written as the raw CDR bytes received (no deserialise/serialise), logged at the
recorder's ROS time on receipt (simulated time with ``--ros-args -p use_sim_time:=true``).
SIGINT and SIGTERM close the file properly; a SIGKILL loses at most the last flush period
(``--flush-period``, 0.5 s of wall time by default): ``ros2 run recorder recover <bag>``.
"""

from __future__ import annotations

import argparse
import sys
from datetime import datetime
from pathlib import Path

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from ato_common.ros import RunNodeHooks, freeze_startup_objects, run_node
from recorder.bag import DEFAULT_FLUSH_PERIOD_S, BagError, BagWriter
from recorder.ros_io import message_class, qos_to_yaml, subscription_qos


class RecorderNode(RunNodeHooks, Node):
    def __init__(self, writer: BagWriter, topics: list[str] | None, discovery_period_s: float):
        super().__init__('recorder')
        self.writer = writer
        self.wanted = set(topics) if topics else None
        self.subscribed: dict[str, object] = {}
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
        wanted = 'all topics' if self.wanted is None else sorted(self.wanted)
        self.get_logger().info(f'recording {wanted} to {writer.path}')
        freeze_startup_objects()

    def discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subscribed or (self.wanted is not None and topic not in self.wanted):
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
            self.writer.add_topic(topic, type_name, qos_to_yaml(offered))
            self.subscribed[topic] = self.create_subscription(
                msg_type, topic, self._callback(topic), subscription_qos(offered), raw=True)
            self.get_logger().info(f'recording {topic} [{type_name}]')

    def _callback(self, topic: str):
        write, clock = self.writer.write, self.get_clock()

        def on_message(data: bytes) -> None:
            if self.finished:
                return
            try:
                write(topic, clock.now().nanoseconds, data)
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
    parser.add_argument('--discovery-period', type=float, default=0.1,
                        help='how often to look for new topics, s')
    return parser.parse_args(argv)


def main(args=None) -> int:
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    options = parse_args(argv)
    output = options.output or Path('runs') / datetime.now().strftime('rec-%Y%m%d-%H%M%S')
    try:
        writer = BagWriter(output, options.compression, flush_period_s=options.flush_period)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    try:
        return run_node(lambda: RecorderNode(writer, options.topics, options.discovery_period),
                        args)
    finally:
        if not writer.closed:  # the node never came up
            try:
                writer.close()
            except BagError as error:
                print(f'error: {error}', file=sys.stderr)


if __name__ == '__main__':
    raise SystemExit(main())
