"""The bag against rosbag2 Jazzy's own format, field by field: metadata.yaml (version 9) and the
MCAP's header, channels, messages and ``rosbag2`` metadata record against fixtures derived from
rosbag2 jazzy's encoders (``fixtures/``); QoS read back in both the version 8 (numbers) and the
version 9 (named) formats, including bags that rosbags writes in Jazzy's format."""

import re
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import Stores, get_typestore

from recorder.bag import BagWriter, bag_file, bag_info, recover
from recorder.ros_io import offered_profiles, replay_qos
from recorder.rosbag2_format import INFINITE_NS, FormatError, parse_qos_profiles

FIXTURES = Path(__file__).parent / 'fixtures'
JAZZY_METADATA = yaml.safe_load((FIXTURES / 'jazzy_metadata.yaml').read_text())
JAZZY_MCAP = yaml.safe_load((FIXTURES / 'jazzy_mcap.yaml').read_text())
STATE_TYPE = 'trajectory_msgs/msg/JointTrajectory'
LOG_TYPE = 'rcl_interfaces/msg/Log'
FOREVER = Duration(nanoseconds=INFINITE_NS)


def reported(durability=DurabilityPolicy.VOLATILE, lifespan=FOREVER,
             reliability=ReliabilityPolicy.RELIABLE) -> QoSProfile:
    """A publisher's profile as rmw reports it to a subscriber (history unknown, depth 0,
    infinities as RMW_DURATION_INFINITE)."""
    return QoSProfile(history=HistoryPolicy.UNKNOWN, depth=0, reliability=reliability,
                      durability=durability, deadline=FOREVER, lifespan=lifespan,
                      liveliness=LivelinessPolicy.AUTOMATIC,
                      liveliness_lease_duration=FOREVER)


STREAM = reported()
ROSOUT = reported(DurabilityPolicy.TRANSIENT_LOCAL, Duration(seconds=10))


def same_shape(expected, actual, where='') -> list[str]:
    """Differences in keys (and their order), nesting and kinds of value."""
    if isinstance(expected, dict):
        if not isinstance(actual, dict):
            return [f'{where}: a mapping expected, got {actual!r}']
        if list(expected) != list(actual):
            return [f'{where}: keys {list(actual)} instead of {list(expected)}']
        return [d for key in expected for d in same_shape(expected[key], actual[key],
                                                          f'{where}.{key}')]
    if isinstance(expected, list):
        if not isinstance(actual, list) or not actual:
            return [f'{where}: a non-empty list expected, got {actual!r}']
        return [d for i, item in enumerate(actual) for d in same_shape(expected[0], item,
                                                                      f'{where}[{i}]')]
    if type(expected) is not type(actual):
        return [f'{where}: {type(expected).__name__} expected, got {actual!r}']
    return []


def state(k: int) -> bytes:
    from rclpy.serialization import serialize_message

    from ato_common.types import TrainState
    from ato_ros.messages import state_to_msg
    return serialize_message(state_to_msg(TrainState(k * 100_000_000, ('car_1',), (k * 1.0,),
                                                     (0.5,), (0.0,), (0.0,))))


@pytest.fixture
def bag(tmp_path):
    from rcl_interfaces.msg import Log
    from rclpy.serialization import serialize_message
    writer = BagWriter(tmp_path / 'run', custom_data={'log_time': 'stamp'})
    writer.add_topic('/train/state', STATE_TYPE, offered_profiles([STREAM]))
    writer.add_topic('/rosout', LOG_TYPE, offered_profiles([ROSOUT]))
    for k in range(1, 51):
        writer.write('/train/state', k * 100_000_000, state(k))
        if k % 5 == 0:
            writer.write('/rosout', k * 100_000_000, serialize_message(Log(msg=f'{k}')))
    writer.close()
    return tmp_path / 'run'


def test_metadata_yaml_has_jazzy_layout_field_by_field(bag):
    written = yaml.safe_load((bag / 'metadata.yaml').read_text())
    assert same_shape(JAZZY_METADATA, written) == []
    info = written['rosbag2_bagfile_information']
    expected = JAZZY_METADATA['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['ros_distro'] == 'jazzy'
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['run_0.mcap'] and info['files'][0]['path'] == \
        'run_0.mcap'
    assert info['duration'] == expected['duration']
    assert info['starting_time'] == expected['starting_time']
    assert info['message_count'] == 60 == sum(t['message_count']
                                             for t in info['topics_with_message_count'])
    assert info['files'][0]['message_count'] == 60
    assert info['custom_data'] == {'log_time': 'stamp'}
    # Offered QoS as offered, named as Jazzy names them; the type hash as rosbags computes it.
    assert info['topics_with_message_count'] == expected['topics_with_message_count']


def test_empty_custom_data_is_null_as_yaml_cpp_writes_an_empty_map(tmp_path):
    writer = BagWriter(tmp_path / 'run')
    writer.add_topic('/train/state', STATE_TYPE, offered_profiles([STREAM]))
    writer.write('/train/state', 1, state(1))
    writer.close()
    text = (tmp_path / 'run' / 'metadata.yaml').read_text()
    assert yaml.safe_load(text)['rosbag2_bagfile_information']['custom_data'] is None
    # sequences indented under their key, as yaml-cpp writes them
    assert '  relative_file_paths:\n    - run_0.mcap\n' in text


def test_mcap_records_are_those_of_jazzys_storage_plugin(bag):
    pattern = re.compile(JAZZY_MCAP['type_hash_pattern'])
    with open(bag_file(bag), 'rb') as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == JAZZY_MCAP['header_profile']
        summary = reader.get_summary()
        for schema in summary.schemas.values():
            assert schema.encoding == JAZZY_MCAP['schema_encoding'] and schema.data
        expected_topics = {t['topic_metadata']['name']: t['topic_metadata'] for t in
                           JAZZY_METADATA['rosbag2_bagfile_information'][
                               'topics_with_message_count']}
        for channel in summary.channels.values():
            assert channel.message_encoding == JAZZY_MCAP['channel_message_encoding']
            assert sorted(channel.metadata) == sorted(JAZZY_MCAP['channel_metadata_keys'])
            assert pattern.match(channel.metadata['topic_type_hash'])
            expected = expected_topics[channel.topic]
            assert channel.metadata['topic_type_hash'] == expected['type_description_hash']
            assert yaml.safe_load(channel.metadata['offered_qos_profiles']) == \
                expected['offered_qos_profiles']
        assert summary.chunk_indexes and {c.compression for c in summary.chunk_indexes} == \
            {JAZZY_MCAP['chunk_compression']}
        messages = [(c.topic, m) for _, c, m in reader.iter_messages()]
        # The two fields of a message that are the SDK writer's, not rosbag2's (recorder.bag):
        # the sequence counts each channel's messages (Jazzy: 0), the publish time is the log
        # time (Jazzy: the publisher's send time).
        for topic in ('/train/state', '/rosout'):
            mine = [m for t, m in messages if t == topic]
            assert [m.sequence for m in mine] == list(range(1, len(mine) + 1))
            assert all(m.publish_time == m.log_time for m in mine)
        records = list(reader.iter_metadata())
    assert [r.name for r in records] == [JAZZY_MCAP['metadata_record']['name']] * len(
        JAZZY_MCAP['metadata_records_written'])
    for record in records:
        assert sorted(record.metadata) == JAZZY_MCAP['metadata_record']['keys']
    at_open, at_close = (yaml.safe_load(r.metadata['serialized_metadata']) for r in records)
    assert same_shape(JAZZY_METADATA['rosbag2_bagfile_information'], at_close) == []
    assert at_close == yaml.safe_load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert_as_at_open(at_open, at_close)


def assert_as_at_open(at_open: dict, at_close: dict) -> None:
    """The record of the open: as rosbag2 Jazzy's writer fills it before any topic (the keys of
    the closing one, in its order; no topic, no message; the same file, custom data and
    distribution)."""
    expected = JAZZY_MCAP['at_open']
    assert list(at_open) == list(at_close)
    for key in ('starting_time', 'duration', 'message_count', 'topics_with_message_count'):
        assert at_open[key] == expected[key], key
    (file,) = at_open['files']
    assert file == {'path': at_close['files'][0]['path'],
                    'starting_time': expected['starting_time'],
                    'duration': expected['duration'],
                    'message_count': expected['files_message_count']}
    for key in ('version', 'storage_identifier', 'relative_file_paths', 'custom_data',
                'ros_distro', 'compression_format', 'compression_mode'):
        assert at_open[key] == at_close[key], key


def test_recover_writes_the_same_records(bag):
    file = bag_file(bag)
    data = file.read_bytes()
    file.write_bytes(data[: len(data) - 200])  # the summary gone
    info = recover(bag).info
    assert info.message_count == 60 and info.custom_data == {'log_time': 'stamp'}
    written = yaml.safe_load((bag / 'metadata.yaml').read_text())
    assert same_shape(JAZZY_METADATA, written) == []
    assert written['rosbag2_bagfile_information']['topics_with_message_count'] == \
        JAZZY_METADATA['rosbag2_bagfile_information']['topics_with_message_count']
    with open(file, 'rb') as stream:
        records = list(make_reader(stream).iter_metadata())
    assert [r.name for r in records] == ['rosbag2', 'rosbag2']
    at_open, at_close = (yaml.safe_load(r.metadata['serialized_metadata']) for r in records)
    assert_as_at_open(at_open, at_close)


VERSION_8 = '''- history: 3
  depth: 0
  reliability: 1
  durability: 1
  deadline:
    sec: 2147483647
    nsec: 4294967295
  lifespan:
    sec: 10
    nsec: 0
  liveliness: 1
  liveliness_lease_duration:
    sec: 2147483647
    nsec: 4294967295
  avoid_ros_namespace_conventions: false
'''


def test_version_8_numbers_and_version_9_names_read_the_same():
    named = JAZZY_METADATA['rosbag2_bagfile_information']['topics_with_message_count'][1][
        'topic_metadata']['offered_qos_profiles']
    assert parse_qos_profiles(VERSION_8) == named  # old infinities read as infinite
    assert parse_qos_profiles(yaml.safe_dump(named)) == named
    for recorded in (VERSION_8, named):
        qos = replay_qos(recorded)
        assert qos.reliability == ReliabilityPolicy.RELIABLE
        assert qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
        assert qos.lifespan.nanoseconds == 10_000_000_000


def test_best_effort_and_volatile_only_where_recorded_so():
    best_effort = offered_profiles([reported(reliability=ReliabilityPolicy.BEST_EFFORT)])
    assert replay_qos(best_effort).reliability == ReliabilityPolicy.BEST_EFFORT
    stream = replay_qos(offered_profiles([STREAM]))
    assert (stream.reliability, stream.durability) == (ReliabilityPolicy.RELIABLE,
                                                       DurabilityPolicy.VOLATILE)


@pytest.mark.parametrize('bad, match', [
    ('- history: keep_most\n', 'without'),
    ([{**JAZZY_METADATA['rosbag2_bagfile_information']['topics_with_message_count'][0][
        'topic_metadata']['offered_qos_profiles'][0], 'reliability': 'sometimes'}], 'sometimes'),
    ([{**JAZZY_METADATA['rosbag2_bagfile_information']['topics_with_message_count'][0][
        'topic_metadata']['offered_qos_profiles'][0], 'durability': 9}], 'policy number'),
    ('{not: [yaml', 'not YAML'),
])
def test_malformed_qos_names_what_is_wrong(bad, match):
    with pytest.raises(FormatError, match=match):
        parse_qos_profiles(bad)


@pytest.mark.parametrize('version', [8, 9])
def test_a_bag_rosbags_writes_in_jazzys_format_replays_reliable_and_latched(tmp_path, version):
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    from rosbags.rosbag2.enums import StoragePlugin
    typestore = get_typestore(Stores.ROS2_JAZZY)
    forever = QosTime(sec=9223372036, nsec=854775807)

    def qos(reliability, durability):
        return Qos(QosHistory.UNKNOWN, 0, reliability, durability, forever, forever,
                   QosLiveliness.AUTOMATIC, forever, False)
    path = tmp_path / 'converted'
    with RosbagsWriter(path, version=version, storage_plugin=StoragePlugin.MCAP) as writer:
        latched = writer.add_connection(
            '/ato/reference/curve', STATE_TYPE, typestore=typestore,
            offered_qos_profiles=[qos(QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)])
        stream = writer.add_connection(
            '/train/state', STATE_TYPE, typestore=typestore,
            offered_qos_profiles=[qos(QosReliability.RELIABLE, QosDurability.VOLATILE)])
        lossy = writer.add_connection(
            '/lossy', STATE_TYPE, typestore=typestore,
            offered_qos_profiles=[qos(QosReliability.BEST_EFFORT, QosDurability.VOLATILE)])
        for connection in (latched, stream, lossy):
            writer.write(connection, 1, state(1))
    info = bag_info(path)
    curve = replay_qos(info.topics['/ato/reference/curve'].offered_qos_profiles)
    assert (curve.reliability, curve.durability) == (ReliabilityPolicy.RELIABLE,
                                                     DurabilityPolicy.TRANSIENT_LOCAL)
    state_qos = replay_qos(info.topics['/train/state'].offered_qos_profiles)
    assert (state_qos.reliability, state_qos.durability) == (ReliabilityPolicy.RELIABLE,
                                                             DurabilityPolicy.VOLATILE)
    lossy_qos = replay_qos(info.topics['/lossy'].offered_qos_profiles)
    assert lossy_qos.reliability == ReliabilityPolicy.BEST_EFFORT
