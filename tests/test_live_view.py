"""The live view (``ros2 run recorder live``) over rclpy and a Foxglove WebSocket client: every
topic is offered with its ROS 2 definition, a watched topic arrives as the publisher's CDR bytes
at its stamp, and the view holds a ROS subscription only while a client watches."""

import os
import queue
import subprocess
import time

import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ato_bringup.runner import run_lockstep
from ato_bringup.stack import Stack, StackConfig, executable_path
from ato_common.conventions import TOPICS
from ato_ros.messages import qos_profile
from ato_ros.middleware import with_middleware_defaults
from recorder.foxglove_client import FoxgloveClient, message_data
from recorder.live import served_url
from recorder.node import BACKGROUND_NICE
from recorder.ros_io import message_class


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
            url = None
            deadline = time.monotonic() + 30
            while url is None and time.monotonic() < deadline:
                stack.spin_for(0.1)
                url = served_url(log.read_text(errors='replace'))
            assert url, log.read_text(errors='replace')
            # by default the view takes only the CPU the run leaves (set before its threads)
            assert os.getpriority(os.PRIO_PROCESS, live.pid) == BACKGROUND_NICE
            client = FoxgloveClient(url)
            try:
                channel = client.channel(topic, 20, lambda: stack.spin_for(0.05))
                assert channel['encoding'] == 'cdr'
                assert channel['schemaName'] == state.type_name
                assert channel['schemaEncoding'] == 'ros2msg'
                assert 'MSG: trajectory_msgs/JointTrajectoryPoint' in channel['schema']
                # offered, not watched: no ROS subscription (the stack's own monitor has one)
                stack.spin_for(1.0)
                others = publisher.get_subscription_count()
                client.subscribe(7, channel['id'])
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
                client.unsubscribe(7)
                assert stack.spin_until(lambda: publisher.get_subscription_count() == others, 20)
            finally:
                client.close()
        finally:
            live.send_signal(2)
            assert live.wait(timeout=30) == 0, log.read_text(errors='replace')
        assert 'Traceback' not in log.read_text(errors='replace')


def test_a_port_already_taken_is_an_error_naming_it(domain_id):
    import socket
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([executable_path('recorder', 'live'), '--port', str(port)],
                                capture_output=True, text=True, timeout=60,
                                env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    assert result.returncode == 2
    assert f'cannot serve Foxglove on 127.0.0.1:{port}' in result.stderr
    assert 'Traceback' not in result.stderr


def test_a_port_that_is_not_a_port_is_refused(tmp_path):
    result = subprocess.run([executable_path('recorder', 'live'), '--port', '70000'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert '70000 is not a port number' in result.stderr


@pytest.mark.parametrize('rate', ['0', '20'], ids=['every message', 'sampled at 20 Hz'])
def test_a_client_watches_a_lockstep_run(tmp_path, domain_id, rate):
    """During a lockstep run, a client subscribed to the train's state receives it, decodable
    and at its stamps: every step with ``--rate 0``, the latest at 20 Hz of wall time by
    default; the run is not held up by the view. The view runs at the test's priority: at nice
    19 (its default, tested above) it takes only the CPU the run and every other process leave,
    which on two cores beside another test's run (make test) or busy processes (make
    test-stress) can be none until the run is over, and it rightly forwards nothing of it."""
    state = TOPICS['state']
    topic = '/' + state.name
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env = with_middleware_defaults(env)  # as the stack's own processes
    log = tmp_path / 'live.log'
    with open(log, 'wb') as out:
        live = subprocess.Popen([executable_path('recorder', 'live'), '--port', '0',
                                 '--rate', rate, topic, '--no-background'],
                                stdout=out, stderr=subprocess.STDOUT, env=env,
                                stdin=subprocess.DEVNULL)
    client = None
    try:
        deadline = time.monotonic() + 30
        url = None
        while url is None and time.monotonic() < deadline:
            time.sleep(0.1)
            url = served_url(log.read_text(errors='replace'))
        assert url, log.read_text(errors='replace')
        client = FoxgloveClient(url)

        def watch(stack):
            channel = client.channel(topic, 30, lambda: stack.spin_for(0.05))
            client.subscribe(3, channel['id'])
            return channel['id']

        outcome = run_lockstep(StackConfig(scenario='short_line', domain_id=domain_id,
                                           end_time_s=150.0, log_dir=tmp_path / 'logs'),
                               actions={5.0: watch})
        assert outcome.metrics.simulated_time_s >= 149.0
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
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        steps = outcome.metrics.samples
        if rate == '0':  # every 0.1 s step from the subscription on to the end
            assert len(stamps) >= 50 and stamps[-1] >= 149_900_000_000, len(stamps)
            assert set(np.diff(stamps)) == {100_000_000}
        else:  # the latest at 20 Hz of the run's wall time, far fewer than the steps
            assert 1 <= len(stamps) <= 20 * outcome.wall_time_s + 5 < steps, len(stamps)
    finally:
        if client is not None:
            client.close()
        live.send_signal(2)
        assert live.wait(timeout=30) == 0, log.read_text(errors='replace')


def test_an_observation_topic_is_sampled_for_a_sampling_subscriber_only(domain_id):
    """The plant and the profile publish an observation topic every step to a subscriber that
    keeps its messages (a recorder: reliable), and at most every SAMPLED_PERIOD_S of wall time
    while every subscriber only samples it (the live view: best effort). Who subscribes is asked
    again every SUBSCRIBERS_REFRESH_S of wall time: a new subscriber is served from then on."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    from ato_ros.publishing import SAMPLED_PERIOD_S, SUBSCRIBERS_REFRESH_S, Observation
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = Node('observed', context=context)
        publisher = node.create_publisher(Float64, '/observed_topic', 10)
        observation = Observation(node, publisher)
        assert not observation.due()  # nobody subscribes

        def wait_for(count):
            deadline = time.monotonic() + 10
            while publisher.get_subscription_count() != count:
                assert time.monotonic() < deadline
                time.sleep(0.01)

        def due_over(seconds):
            end, dues, calls = time.monotonic() + seconds, 0, 0
            while time.monotonic() < end:
                dues += observation.due()
                calls += 1
            return dues, calls

        sampling = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                              reliability=ReliabilityPolicy.BEST_EFFORT)
        node.create_subscription(Float64, '/observed_topic', lambda m: None, sampling)
        wait_for(1)
        dues, calls = due_over(0.2)
        assert 1 <= dues <= 0.2 / SAMPLED_PERIOD_S + 2 < calls
        node.create_subscription(Float64, '/observed_topic', lambda m: None, 10)  # keeps them
        wait_for(2)
        time.sleep(SUBSCRIBERS_REFRESH_S)
        dues, calls = due_over(0.05)
        assert dues == calls
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


class LiveView:
    """``recorder live`` (its log in ``log``) and the URL it serves."""

    def __init__(self, log, env, *args):
        self.log = log
        with open(log, 'wb') as out:
            self.process = subprocess.Popen(
                [executable_path('recorder', 'live'), '--port', '0', *args], stdout=out,
                stderr=subprocess.STDOUT, env=env, stdin=subprocess.DEVNULL)
        deadline, self.url = time.monotonic() + 30, None
        while self.url is None and time.monotonic() < deadline:
            time.sleep(0.1)
            self.url = served_url(log.read_text(errors='replace'))
        assert self.url, log.read_text(errors='replace')

    def stop(self) -> None:
        self.process.send_signal(2)
        assert self.process.wait(timeout=30) == 0, self.log.read_text(errors='replace')
        assert 'Traceback' not in self.log.read_text(errors='replace')


def stack_env(domain_id):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return with_middleware_defaults(env)  # as the stack's own processes


def test_the_protocol_by_either_name_and_a_clear_refusal_otherwise(tmp_path, domain_id):
    """Issue 31, defect 2: the SDK's name of the protocol (foxglove.sdk.v1) and its former name
    (foxglove.websocket.v1) both connect, each answered with the name it asked for, and get the
    same channels; a request for neither is refused with HTTP 400 and a text saying which to ask
    for. The step records and acknowledgements are not offered unless named."""
    import urllib.error
    import urllib.request

    from recorder.ws_front import OLDER_SUBPROTOCOL, SDK_SUBPROTOCOL
    with Stack(StackConfig(scenario='short_line', domain_id=domain_id,
                           log_dir=tmp_path)) as stack:
        for key in ('state', 'step_records', 'recorded'):
            spec = TOPICS[key]
            stack.node.create_publisher(message_class(spec.type_name), '/' + spec.name,
                                        qos_profile(spec.qos))
        live = LiveView(tmp_path / 'live.log', stack.env)
        named = LiveView(tmp_path / 'named.log', stack.env, '/ato/step_records')
        try:
            for subprotocol in (SDK_SUBPROTOCOL, OLDER_SUBPROTOCOL):
                client = FoxgloveClient(live.url, subprotocol=subprotocol)
                try:
                    assert client.connection.selected_subprotocol == subprotocol
                    client.channel('/train/state', 20, lambda: stack.spin_for(0.05))
                    stack.spin_for(2.0)  # every topic of the graph is offered by now
                    assert '/ato/step_records' not in client.channels
                    assert '/ato/recorded' not in client.channels
                finally:
                    client.close()
            client = FoxgloveClient(named.url)
            try:
                client.channel('/ato/step_records', 20, lambda: stack.spin_for(0.05))
            finally:
                client.close()
            request = urllib.request.Request(live.url.replace('ws://', 'http://'), headers={
                'Connection': 'Upgrade', 'Upgrade': 'websocket',
                'Sec-WebSocket-Version': '13', 'Sec-WebSocket-Key': 'dGhlIHNhbXBsZSBub25jZQ==',
                'Sec-WebSocket-Protocol': 'some.other.v1'})
            with pytest.raises(urllib.error.HTTPError) as refused:
                urllib.request.urlopen(request, timeout=10)
            assert refused.value.code == 400
            text = refused.value.read().decode()
            assert SDK_SUBPROTOCOL in text and OLDER_SUBPROTOCOL in text
            assert 'some.other.v1' in text
        finally:
            live.stop()
            named.stop()


def lose_steps(first_s: float, last_s: float):
    """An action on the stack: the monitor's samples from ``first_s`` to ``last_s`` of simulated
    time forgotten, as a monitor that fell behind the loop further than the middleware keeps
    for it never gets them."""
    def lose(stack):
        for stamp in [k for k in stack.monitor.samples if first_s * 1e9 <= k <= last_s * 1e9]:
            del stack.monitor.samples[stamp]
    return lose


def test_a_watched_multi_car_run_is_summed_up_over_every_step(tmp_path, domain_id):
    """Issue 31, defect 1: a multi-car run (mao_4car, the multi-car plant, to its end) as
    run_scenario runs it (the lean monitor, recorded), watched in Foxglove by a client subscribed
    to topics of the shipped layout. The live view and the app beside it starved the run's
    monitor of CPU, and the summary was that of part of the run. Here the monitor is stalled
    outright for a while (its thread takes nothing), and the steps from 30 s to 60 s are taken
    from it, as the middleware dropped those of a monitor that fell too far behind. The summary
    still covers every step: those the monitor missed come from the recording, which the loop
    waits for (and a run without one fails, naming them: tests/test_run_complete.py)."""
    from ato_bringup.stack import RUN_DIAGNOSTICS_PERIOD_S

    live = LiveView(tmp_path / 'live.log', stack_env(domain_id))
    client = FoxgloveClient(live.url)
    try:
        def watch(stack):
            for k, topic in enumerate(('/train/state', '/ato/reference', '/ato/command',
                                       '/train/actuators/applied', '/diagnostics')):
                client.subscribe(k, client.channel(topic, 30, lambda: stack.spin_for(0.02))['id'])

        config = StackConfig(scenario='mao_4car', controller='mao_multibody_rigid',
                             domain_id=domain_id, log_dir=tmp_path / 'logs',
                             record_to=tmp_path / 'bag', monitor='lean',
                             plant_params={'model': 'multi_car'},
                             diagnostics_period_s=RUN_DIAGNOSTICS_PERIOD_S)
        outcome = run_lockstep(config, actions={0.0: watch,
                                                20.0: lambda stack: time.sleep(10.0),
                                                100.0: lose_steps(30.0, 60.0)})
        watched = sum(isinstance(m, bytes) for m in list(client.received.queue))
    finally:
        client.close()
        live.stop()
    end_ns = round(config.end_time_s * 1e9)  # the scenario's end, set by the run
    expected = list(range(0, end_ns + 99_999_999, 100_000_000))  # 10 Hz, to the first at the end
    assert len(expected) > 11_000
    assert [k for k, _ in outcome.samples] == expected
    assert all(len(s.positions) == 4 for _, s in outcome.samples)  # every car, every step
    assert outcome.metrics.samples == len(expected)
    assert outcome.metrics.simulated_time_s == pytest.approx(expected[-1] / 1e9)
    assert watched > 0


def test_the_loop_waits_for_a_live_view_besides_the_monitor_and_the_controller(tmp_path,
                                                                                domain_id):
    """Each loop node waits for a number of readers, not for names: a live view that subscribes
    to the state, the reference and /diagnostics before the run starts is counted as well
    (StackConfig.watched_by), or the view's reader, matched first, would let the loop start
    before the monitor is matched and the monitor would miss the first steps."""
    def waits(watched_by):
        with Stack(StackConfig(scenario='short_line', domain_id=domain_id, monitor='lean',
                               log_dir=tmp_path / 'logs', watched_by=watched_by)) as stack:
            params = stack.node_params()
        return {name: (params[name]['wait_for_subscribers'],
                       params[name]['wait_for_diagnostics_readers'])
                for name in ('plant', 'profile', 'controller')}
    alone = waits(())
    watched = waits(('state', 'reference', 'diagnostics'))
    assert watched['plant'] == (alone['plant'][0] + 1, alone['plant'][1] + 1)
    assert watched['profile'] == (alone['profile'][0] + 1, alone['profile'][1] + 1)
    assert watched['controller'] == (alone['controller'][0], alone['controller'][1] + 1)
