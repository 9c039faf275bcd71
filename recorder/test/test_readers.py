"""A recording read by the latest releases of rosbags and mcap-ros2-support, installed in a
virtual environment of their own (not the suite's pinned ones): every message decodes, and
rosbags opens the bag (metadata.yaml version 9) with the offered QoS and type hashes as
written."""

import json
import subprocess
import venv

import pytest
from rcl_interfaces.msg import Log
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock

from ato_common.types import TrainState
from ato_ros.messages import state_to_msg, to_time
from recorder.bag import BagWriter
from recorder.ros_io import offered_profiles
from recorder.rosbag2_format import type_hash

READERS = ('rosbags', 'mcap-ros2-support')

SCRIPT = r'''
import json, sys
from pathlib import Path
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from importlib.metadata import version

bag = Path(sys.argv[1])
store = get_typestore(Stores.ROS2_JAZZY)
out = {'versions': {p: version(p) for p in ('rosbags', 'mcap', 'mcap-ros2-support')}}
with Reader(bag) as reader:
    out['rosbags_connections'] = {
        c.topic: {'type': c.msgtype, 'count': c.msgcount, 'digest': c.digest,
                  'qos': [[q.reliability.name, q.durability.name, q.lifespan.sec]
                          for q in c.ext.offered_qos_profiles]}
        for c in reader.connections}
    out['rosbags_decoded'] = sum(1 for c, _, raw in reader.messages()
                                 if store.deserialize_cdr(raw, c.msgtype) is not None)
with open(next(bag.glob('*.mcap')), 'rb') as stream:
    reader = make_reader(stream, decoder_factories=[DecoderFactory()])
    out['mcap_decoded'] = sum(1 for _ in reader.iter_decoded_messages())
print(json.dumps(out))
'''


@pytest.fixture(scope='module')
def latest_readers(tmp_path_factory):
    """A venv with the readers' latest releases; skipped when pip cannot reach the index."""
    folder = tmp_path_factory.mktemp('readers')
    venv.EnvBuilder(with_pip=True).create(folder / 'venv')
    python = folder / 'venv' / 'bin' / 'python'
    result = subprocess.run([python, '-m', 'pip', 'install', '--quiet', '--disable-pip-version-'
                             'check', '--no-input', '--timeout', '30', *READERS],
                            capture_output=True, text=True, timeout=900)
    if result.returncode != 0:
        pytest.skip(f'pip could not install the latest {", ".join(READERS)} from the package '
                    f'index: {result.stderr.strip().splitlines()[-1:]}')
    return python


def test_the_latest_rosbags_and_mcap_ros2_read_every_message(latest_readers, tmp_path):
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile

    from recorder.rosbag2_format import INFINITE_NS
    forever = Duration(nanoseconds=INFINITE_NS)

    def offered(durability, lifespan=forever):
        return offered_profiles([QoSProfile(
            history=HistoryPolicy.UNKNOWN, depth=0, durability=durability, deadline=forever,
            lifespan=lifespan, liveliness=LivelinessPolicy.AUTOMATIC,
            liveliness_lease_duration=forever)])
    writer = BagWriter(tmp_path / 'run')
    writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock', offered(DurabilityPolicy.VOLATILE))
    writer.add_topic('/train/state', 'trajectory_msgs/msg/JointTrajectory',
                     offered(DurabilityPolicy.VOLATILE))
    writer.add_topic('/rosout', 'rcl_interfaces/msg/Log',
                     offered(DurabilityPolicy.TRANSIENT_LOCAL, Duration(seconds=10)))
    for k in range(100):
        stamp = k * 100_000_000
        writer.write('/clock', stamp, serialize_message(Clock(clock=to_time(stamp))))
        writer.write('/train/state', stamp, serialize_message(state_to_msg(TrainState(
            stamp, ('car_1', 'car_2'), (k * 1.0, k - 25.0), (1.0, 1.0), (0.0, 0.0),
            (1e3, -2e3)))))
        if k % 10 == 0:
            writer.write('/rosout', stamp, serialize_message(Log(msg=f'step {k}')))
    writer.close()
    result = subprocess.run([latest_readers, '-c', SCRIPT, str(tmp_path / 'run')],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    print('readers:', out['versions'])
    assert out['rosbags_decoded'] == out['mcap_decoded'] == 210
    connections = out['rosbags_connections']
    assert connections['/rosout']['qos'] == [['RELIABLE', 'TRANSIENT_LOCAL', 10]]
    assert connections['/train/state']['qos'] == [['RELIABLE', 'VOLATILE', 9223372036]]
    for topic, connection in connections.items():
        assert connection['digest'] == type_hash(connection['type']), topic
