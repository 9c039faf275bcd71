"""The live view (``ros2 run recorder live``) over rclpy and a Foxglove WebSocket client: every
topic is offered with its ROS 2 definition, a watched topic arrives as the publisher's CDR bytes
at its stamp, and the view holds a ROS subscription only while a client watches."""

import asyncio
import json
import os
import queue
import re
import struct
import subprocess
import threading
import time

import pytest
from rclpy.serialization import deserialize_message
from tornado.websocket import websocket_connect
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ato_bringup.runner import run_lockstep
from ato_bringup.stack import Stack, StackConfig, executable_path
from ato_common.conventions import TOPICS
from ato_common.ros import qos_profile

SUBPROTOCOL = 'foxglove.sdk.v1'


class FoxgloveClient:
    """A Foxglove WebSocket protocol client on a thread of its own: text frames (JSON) and
    binary frames land in ``received``."""

    def __init__(self, url: str):
        self.received: queue.Queue = queue.Queue()
        self.loop = asyncio.new_event_loop()
        self.connected = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(url,), daemon=True)
        self.thread.start()
        assert self.connected.wait(10), 'no WebSocket connection'

    def _run(self, url: str) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(self._connect(url))
        self.loop.run_forever()

    async def _connect(self, url: str) -> None:
        self.connection = await websocket_connect(url, subprotocols=[SUBPROTOCOL])
        self.connected.set()
        self.loop.create_task(self._read())

    async def _read(self) -> None:
        while True:
            message = await self.connection.read_message()
            if message is None:
                return
            self.received.put(message)

    def send(self, payload: dict) -> None:
        self.loop.call_soon_threadsafe(self.connection.write_message, json.dumps(payload))

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.connection.close)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)

    def next(self, accept, timeout_s: float, spin) -> object:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            spin()
            try:
                message = self.received.get(timeout=0.05)
            except queue.Empty:
                continue
            found = accept(message)
            if found is not None:
                return found
        pytest.fail('nothing the test waited for arrived from the live view')


def advertised(topic):
    def accept(message):
        if isinstance(message, str):
            body = json.loads(message)
            for channel in body.get('channels', []) if body.get('op') == 'advertise' else []:
                if channel['topic'] == topic:
                    return channel
        return None
    return accept


def message_data(subscription_id):
    def accept(message):
        if isinstance(message, bytes) and message[0] == 0x01:
            sid, log_time = struct.unpack_from('<IQ', message, 1)
            if sid == subscription_id:
                return log_time, message[13:]
        return None
    return accept


def test_a_watched_topic_arrives_as_published_and_costs_nothing_unwatched(tmp_path, domain_id):
    state = TOPICS['state']
    topic = '/' + state.name
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path)) as stack:
        publisher = stack.node.create_publisher(JointTrajectory, topic, qos_profile(state.qos))
        log = tmp_path / 'live.log'
        with open(log, 'wb') as out:
            live = subprocess.Popen([executable_path('recorder', 'live'), '--port', '0'],
                                    stdout=out, stderr=subprocess.STDOUT, env=stack.env,
                                    stdin=subprocess.DEVNULL)
        try:
            found = None
            deadline = time.monotonic() + 30
            while found is None and time.monotonic() < deadline:
                stack.spin_for(0.1)
                found = re.search(r'ws://127\.0\.0\.1:(\d+)', log.read_text(errors='replace'))
            assert found, log.read_text(errors='replace')
            client = FoxgloveClient(f'ws://127.0.0.1:{found.group(1)}')
            try:
                channel = client.next(advertised(topic), 20, lambda: stack.spin_for(0.05))
                assert channel['encoding'] == 'cdr'
                assert channel['schemaName'] == state.type_name
                assert channel['schemaEncoding'] == 'ros2msg'
                assert 'MSG: trajectory_msgs/JointTrajectoryPoint' in channel['schema']
                # offered, not watched: no ROS subscription (the stack's own monitor has one)
                stack.spin_for(1.0)
                others = publisher.get_subscription_count()
                client.send({'op': 'subscribe',
                             'subscriptions': [{'id': 7, 'channelId': channel['id']}]})
                assert stack.spin_until(
                    lambda: publisher.get_subscription_count() == others + 1, 20)
                message = JointTrajectory(joint_names=['car_1'],
                                          points=[JointTrajectoryPoint(positions=[1234.5])])
                message.header.stamp.sec, message.header.stamp.nanosec = 12, 500_000_000
                stack.spin_for(0.5)  # the new subscription matched on both sides
                publisher.publish(message)
                log_time, payload = client.next(message_data(7), 20,
                                                lambda: stack.spin_for(0.05))
                # the publisher's CDR bytes (compared decoded: CDR's padding bytes are unspecified)
                received = deserialize_message(payload, JointTrajectory)
                assert received.joint_names == ['car_1']
                assert list(received.points[0].positions) == [1234.5]
                assert log_time == 12_500_000_000
                client.send({'op': 'unsubscribe', 'subscriptionIds': [7]})
                assert stack.spin_until(lambda: publisher.get_subscription_count() == others, 20)
            finally:
                client.close()
        finally:
            live.send_signal(2)
            assert live.wait(timeout=30) == 0, log.read_text(errors='replace')
        assert 'Traceback' not in log.read_text(errors='replace')


def test_a_port_that_is_not_a_port_is_refused(tmp_path):
    result = subprocess.run([executable_path('recorder', 'live'), '--port', '70000'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert '70000 is not a port number' in result.stderr


def test_a_client_watches_a_lockstep_run(tmp_path, domain_id):
    """During a lockstep run, a client subscribed to the train's state receives it, decodable
    and at its stamps; the run is not held up by the view."""
    state = TOPICS['state']
    topic = '/' + state.name
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'SHM')  # as the stack's own processes
    log = tmp_path / 'live.log'
    with open(log, 'wb') as out:
        live = subprocess.Popen([executable_path('recorder', 'live'), '--port', '0', topic],
                                stdout=out, stderr=subprocess.STDOUT, env=env,
                                stdin=subprocess.DEVNULL)
    client = None
    try:
        deadline = time.monotonic() + 30
        found = None
        while found is None and time.monotonic() < deadline:
            time.sleep(0.1)
            found = re.search(r'ws://127\.0\.0\.1:(\d+)', log.read_text(errors='replace'))
        assert found, log.read_text(errors='replace')
        client = FoxgloveClient(f'ws://127.0.0.1:{found.group(1)}')

        def watch(stack):
            channel = client.next(advertised(topic), 30, lambda: stack.spin_for(0.05))
            client.send({'op': 'subscribe',
                         'subscriptions': [{'id': 3, 'channelId': channel['id']}]})
            return channel['id']

        outcome = run_lockstep(StackConfig(scenario='short_line', domain_id=domain_id,
                                           end_time_s=60.0, log_dir=tmp_path / 'logs'),
                               actions={5.0: watch})
        assert outcome.metrics.simulated_time_s >= 59.0
        stamps = []
        while True:
            try:
                message = client.received.get(timeout=2.0)
            except queue.Empty:
                break
            data = message_data(3)(message)
            if data is not None:
                log_time, payload = data
                decoded = deserialize_message(payload, JointTrajectory)
                stamp = decoded.header.stamp.sec * 1_000_000_000 + decoded.header.stamp.nanosec
                assert log_time == stamp
                stamps.append(stamp)
        assert len(stamps) >= 100, len(stamps)  # 10 Hz steps from about 5 s to 60 s
        assert stamps == sorted(stamps) and stamps[-1] >= 59_000_000_000
    finally:
        if client is not None:
            client.close()
        live.send_signal(2)
        assert live.wait(timeout=30) == 0, log.read_text(errors='replace')
