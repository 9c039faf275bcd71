"""Round trips of the bag core in a temporary folder: write, read back with independent readers,
break the file, recover it."""

import os
import shutil
from functools import lru_cache

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from ato_common.types import TrainState
from ato_ros.messages import state_to_msg
from recorder.bag import (
    COMPRESSIONS_IN_FILE,
    BagError,
    BagWriter,
    bag_file,
    bag_info,
    read_messages,
    recover,
)
from recorder.cli import info_main, recover_main
from recorder.definitions import full_definition
from recorder.ros_io import offered_profiles, replay_qos

STATE_TYPE = 'trajectory_msgs/msg/JointTrajectory'


@lru_cache(maxsize=None)
def state_bytes(k: int) -> bytes:
    """The bytes of state ``k``, the same bytes each time (rclpy leaves the alignment padding of
    a serialised message as it finds it in memory: two serialisations may differ there)."""
    state = TrainState(k * 100_000_000, ('car_1', 'car_2'), (k * 1.0, k * 1.0 - 25.0),
                       (k * 0.5, k * 0.5), (0.1, 0.1), (1000.0 * k, 0.0))
    return serialize_message(state_to_msg(state))


def write_bag(folder, count=100, **options):
    writer = BagWriter(folder, **options)
    writer.add_topic('/train/state', STATE_TYPE, offered_profiles([QoSProfile(depth=10)]))
    for k in range(count):
        writer.write('/train/state', k * 100_000_000, state_bytes(k))
    return writer


def test_definition_carries_every_dependency():
    text = full_definition(STATE_TYPE)
    for dependency in ('MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time',
                       'MSG: trajectory_msgs/JointTrajectoryPoint',
                       'MSG: builtin_interfaces/Duration'):
        assert dependency in text
    assert text.count('MSG: builtin_interfaces/Time') == 1


def test_round_trip_with_the_mcap_ros2_decoder(tmp_path):
    info = write_bag(tmp_path / 'run').close()
    assert info.message_count == 100 and info.duration_s == pytest.approx(9.9)
    with open(bag_file(tmp_path / 'run'), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        decoded = list(reader.iter_decoded_messages())
    assert len(decoded) == 100
    schema, channel, message, msg = decoded[42]
    assert schema.encoding == 'ros2msg' and channel.message_encoding == 'cdr'
    assert channel.metadata['offered_qos_profiles'].startswith('- history')
    assert msg.joint_names == ['car_1', 'car_2']
    assert list(msg.points[0].positions) == [42.0, 17.0]
    assert msg.header.stamp.sec == 4 and msg.header.stamp.nanosec == 200_000_000
    # raw bytes come back unchanged
    raw = [m.data for m in read_messages(tmp_path / 'run')]
    assert raw == [state_bytes(k) for k in range(100)]


def test_a_bundle_of_step_records_is_written_as_its_messages_one_by_one(tmp_path):
    """write_indexed (a bundle's entries, the recorder's common case) writes the bag that
    write_many writes of the same messages."""
    from ato_ros.step_records import Bundle, read_bundle
    bundle = Bundle(period_s=1e9, wall_period_s=1e9)
    messages = [(topic, k * 100_000_000, state_bytes(k + offset)) for k in range(20)
                for topic, offset in (('/train/state', 0), ('/train/state/measured', 50))]
    for message in messages:
        bundle.add(*message)
    bags = []
    for name, write in (('indexed', lambda w: w.write_indexed(*read_bundle(bundle.take()))),
                        ('many', lambda w: w.write_many(messages))):
        writer = BagWriter(tmp_path / name)
        for topic in ('/train/state/measured', '/train/state'):
            writer.add_topic(topic, STATE_TYPE, offered_profiles([QoSProfile(depth=10)]))
        write(writer)
        info = writer.close()
        bags.append(([(m.topic, m.log_time_ns, m.data) for m in read_messages(tmp_path / name)],
                     {t: i.message_count for t, i in info.topics.items()},
                     (info.start_ns, info.end_ns)))
    assert bags[0] == bags[1]
    assert bags[0][1] == {'/train/state': 20, '/train/state/measured': 20}


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_chunks_are_compressed_when_asked_and_read_back(tmp_path, compression):
    write_bag(tmp_path / 'run', compression=compression).close()
    with open(bag_file(tmp_path / 'run'), 'rb') as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    assert chunks and {c.compression for c in chunks} == {compression}
    assert [m.data for m in read_messages(tmp_path / 'run')] == [state_bytes(k)
                                                                  for k in range(100)]


def test_an_unknown_compression_is_refused_naming_the_ones_there_are(tmp_path):
    with pytest.raises(BagError, match="compression 'gzip' is not one of zstd, lz4, none"):
        BagWriter(tmp_path / 'run', compression='gzip')
    assert not (tmp_path / 'run').exists()


def test_the_folder_is_a_rosbag2_bag_that_rosbags_reads(tmp_path):
    write_bag(tmp_path / 'run').close()
    metadata = yaml.safe_load((tmp_path / 'run' / 'metadata.yaml').read_text())
    assert metadata['rosbag2_bagfile_information']['storage_identifier'] == 'mcap'
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(tmp_path / 'run') as reader:
        assert [(c.topic, c.msgtype, c.msgcount) for c in reader.connections] == \
            [('/train/state', STATE_TYPE, 100)]
        messages = [typestore.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert len(messages) == 100 and list(messages[7].points[0].velocities) == [3.5, 3.5]


def test_info_lists_topics_counts_and_times(tmp_path, capsys):
    write_bag(tmp_path / 'run').close()
    info = bag_info(tmp_path / 'run')
    assert info.topics['/train/state'].message_count == 100
    assert info.start_ns == 0 and info.end_ns == 9_900_000_000
    assert info_main([str(tmp_path / 'run')]) == 0
    out = capsys.readouterr().out
    assert '/train/state' in out and '100' in out and 'duration:  9.900 s' in out


def test_unknown_type_is_recorded_with_a_warning(tmp_path):
    writer = BagWriter(tmp_path / 'run')
    writer.add_topic('/custom', 'nowhere_msgs/msg/Thing')
    writer.write('/custom', 5, b'\x00\x01\x00\x00abc')
    info = writer.close()
    assert info.topics['/custom'].message_count == 1
    assert any('nowhere_msgs/msg/Thing' in w for w in writer.warnings)


def test_refuses_to_overwrite_a_recording(tmp_path):
    write_bag(tmp_path / 'run').close()
    with pytest.raises(BagError, match='exists and is not empty'):
        BagWriter(tmp_path / 'run')


def test_not_an_mcap_file_gives_a_clear_error(tmp_path, capsys):
    bogus = tmp_path / 'bogus.mcap'
    bogus.write_bytes(b'this is not a recording at all' * 10)
    with pytest.raises(BagError, match='is not an MCAP file'):
        list(read_messages(bogus))
    assert info_main([str(bogus)]) == 2
    err = capsys.readouterr().err
    assert 'is not an MCAP file' in err and 'Traceback' not in err
    with pytest.raises(BagError, match='does not exist'):
        bag_info(tmp_path / 'missing.mcap')


def test_truncated_file_names_the_problem_and_recover_restores_what_it_holds(tmp_path, capsys):
    write_bag(tmp_path / 'run', count=2000, chunk_size=4096).close()
    file = bag_file(tmp_path / 'run')
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match='truncated or corrupt.*recover'):
        list(read_messages(tmp_path / 'run'))
    assert recover_main([str(tmp_path / 'run')]) == 0
    assert 'recovered' in capsys.readouterr().out
    recovered = [m.data for m in read_messages(tmp_path / 'run')]
    assert 200 < len(recovered) < 2000  # roughly the half before the cut
    assert recovered == [state_bytes(k) for k in range(len(recovered))]  # a prefix, in order
    assert (file.parent / (file.name + '.damaged')).exists()
    assert bag_info(tmp_path / 'run').message_count == len(recovered)


@pytest.mark.parametrize('compression', ['none', 'zstd', 'lz4'])
def test_recover_writes_the_chunks_compressed_as_the_damaged_file_had_them(tmp_path,
                                                                            compression):
    write_bag(tmp_path / 'run', count=2000, chunk_size=4096, compression=compression).close()
    file = bag_file(tmp_path / 'run')
    file.write_bytes(file.read_bytes()[:file.stat().st_size // 2])
    assert not recover(tmp_path / 'run').intact
    with open(file, 'rb') as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    assert chunks and {c.compression for c in chunks} == {COMPRESSIONS_IN_FILE[compression]}
    recovered = [m.data for m in read_messages(tmp_path / 'run')]
    assert recovered == [state_bytes(k) for k in range(len(recovered))] and recovered


def test_recover_of_a_file_cut_before_its_first_chunk_gives_an_empty_valid_bag(tmp_path):
    write_bag(tmp_path / 'run', count=50, compression='lz4').close()
    file = bag_file(tmp_path / 'run')
    file.write_bytes(file.read_bytes()[:60])  # inside the header: no chunk to read
    result = recover(tmp_path / 'run')
    assert not result.intact and result.info.message_count == 0
    assert list(read_messages(tmp_path / 'run')) == []


def test_recover_leaves_an_intact_bag_alone_and_says_so(tmp_path, capsys):
    write_bag(tmp_path / 'run', count=50).close()
    file = bag_file(tmp_path / 'run')
    before = file.read_bytes(), (tmp_path / 'run' / 'metadata.yaml').read_text()
    result = recover(tmp_path / 'run')
    assert result.intact and result.lost_bytes == 0 and result.info.message_count == 50
    assert recover_main([str(tmp_path / 'run')]) == 0
    out = capsys.readouterr().out
    assert 'is intact' in out and 'nothing to recover' in out and 'could not be read' not in out
    assert (file.read_bytes(), (tmp_path / 'run' / 'metadata.yaml').read_text()) == before
    assert sorted(p.name for p in (tmp_path / 'run').iterdir()) == ['metadata.yaml', file.name]


def test_a_killed_recording_keeps_its_custom_data_and_log_time(tmp_path):
    writer = write_bag(tmp_path / 'run', count=30, custom_data={'log_time': 'stamp',
                                                                'operator': 'lab3'})
    writer.flush()
    killed = tmp_path / 'killed'
    killed.mkdir()
    shutil.copy(writer.path, killed / 'killed_0.mcap')  # as a SIGKILL leaves it: no metadata.yaml
    writer.close()
    info = recover(killed).info
    assert info.message_count == 30
    assert info.custom_data == {'log_time': 'stamp', 'operator': 'lab3'}
    metadata = yaml.safe_load((killed / 'metadata.yaml').read_text())
    assert metadata['rosbag2_bagfile_information']['custom_data'] == info.custom_data
    assert bag_info(killed).custom_data == info.custom_data


def test_an_unclosed_recording_keeps_what_was_flushed(tmp_path):
    writer = write_bag(tmp_path / 'run', count=300, chunk_size=1 << 20)
    writer.flush()  # what the recorder does every flush period
    for k in range(300, 320):  # written after the last flush: may be lost
        writer.write('/train/state', k * 100_000_000, state_bytes(k))
    killed = tmp_path / 'killed'
    killed.mkdir()
    shutil.copy(writer.path, killed / 'killed_0.mcap')  # the file as a SIGKILL leaves it
    with pytest.raises(BagError):
        list(read_messages(killed))
    assert recover(killed).info.message_count >= 300


def test_offered_qos_round_trip_keeps_latched_topics_latched():
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    assert replay_qos(offered_profiles([latched])).durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert replay_qos(offered_profiles([QoSProfile(depth=5)])).durability == \
        DurabilityPolicy.VOLATILE
    mixed = offered_profiles([latched, QoSProfile(depth=5)])
    assert replay_qos(mixed).durability == DurabilityPolicy.VOLATILE


def test_a_corrupt_chunk_gives_a_clear_error_and_recover_keeps_the_original_safe(tmp_path):
    # Chunks by size only (no wall-clock flush), so the damaged bytes land at the same place
    # in the file however loaded the machine is.
    write_bag(tmp_path / 'run', count=2000, chunk_size=4096, flush_period_s=3600.0).close()
    file = bag_file(tmp_path / 'run')
    data = bytearray(file.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 200] = bytes(200)
    file.write_bytes(bytes(data))
    with pytest.raises(BagError, match='(truncated or corrupt|is damaged).*recover'):
        list(read_messages(tmp_path / 'run'))
    info = recover(tmp_path / 'run').info
    assert 0 < info.message_count < 2000
    assert (file.parent / (file.name + '.damaged')).read_bytes() == bytes(data)
    assert len(list(read_messages(tmp_path / 'run'))) == info.message_count


def descriptor_of(path) -> int:
    """This process's file descriptor open on ``path``."""
    (found,) = [int(fd) for fd in os.listdir('/proc/self/fd')
                if os.path.realpath(f'/proc/self/fd/{fd}') == str(path)]
    return found


def test_a_full_disk_stops_the_recording_with_a_clear_error_and_no_valid_looking_bag(
        tmp_path, monkeypatch):
    from collections import namedtuple

    from recorder import bag
    writer = write_bag(tmp_path / 'run', count=10, chunk_size=1 << 20)
    full = os.open('/dev/full', os.O_WRONLY)
    os.dup2(full, descriptor_of(writer.path))  # from now on every write fails with ENOSPC
    # and the disk says it is full, as a full one would
    usage = namedtuple('usage', 'total used free')
    monkeypatch.setattr(bag.shutil, 'disk_usage', lambda path: usage(1 << 30, 1 << 30, 0))
    os.close(full)
    with pytest.raises(BagError, match='No space left on device.*recover'):
        for k in range(10, 20000):
            writer.write('/train/state', k * 100_000_000, state_bytes(k))
        writer.flush()
    with pytest.raises(BagError, match='could not be finished'):
        writer.close()
    assert not (tmp_path / 'run' / 'metadata.yaml').exists()


def test_a_writer_released_at_the_exit_fails_clearly_and_leaves_no_valid_looking_bag(
        tmp_path, monkeypatch):
    """At the interpreter's exit the SDK's writers not yet closed are released; a recorder
    still writing then gets a BagError naming the cause (not an AttributeError), and its bag
    is not finished as if it were whole."""
    import weakref

    from recorder import bag
    writer = write_bag(tmp_path / 'run', count=10)
    monkeypatch.setattr(bag, '_open_writers', weakref.WeakSet([writer]))
    bag._drop_open_writers()
    with pytest.raises(BagError, match="released at the interpreter's exit.*recover"):
        writer.flush()
    with pytest.raises(BagError, match='could not be finished'):
        writer.close()
    assert not (tmp_path / 'run' / 'metadata.yaml').exists()


def test_recover_of_a_file_that_is_not_mcap_says_so_and_leaves_it_untouched(tmp_path, capsys):
    bogus = tmp_path / 'bogus.mcap'
    content = b'certainly not an MCAP recording\n' * 50
    bogus.write_bytes(content)
    with pytest.raises(BagError, match='is not an MCAP file.*left untouched'):
        recover(bogus)
    assert recover_main([str(bogus)]) == 2
    err = capsys.readouterr().err
    assert 'is not an MCAP file' in err and 'Traceback' not in err
    assert bogus.read_bytes() == content
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bogus.mcap']  # no bag, no .damaged


def test_chunks_are_flushed_by_log_time_as_well_as_by_wall_time(tmp_path):
    # No wall-clock flush within the test; 0.25 s of log time between flushes.
    writer = write_bag(tmp_path / 'run', count=0, chunk_size=1 << 24, flush_period_s=3600.0,
                       flush_period_log_s=0.25)
    kept = []
    for k in range(20):  # 0.1 s of log time apart
        writer.write('/train/state', k * 100_000_000, state_bytes(k))
        killed = tmp_path / f'killed{k}'
        killed.mkdir()
        shutil.copy(writer.path, killed / f'killed{k}_0.mcap')  # as a SIGKILL leaves it
        kept.append(recover(killed).info.message_count)
    # a chunk closed every 0.3 s: at the first write at or past 0.25 s since the last one
    assert kept == [0, 0, 0, 4, 4, 4, 7, 7, 7, 10, 10, 10, 13, 13, 13, 16, 16, 16, 19, 19]


@pytest.mark.parametrize('period', [0.0, -1.0, float('nan'), float('inf')])
def test_a_flush_period_must_be_positive_and_finite(tmp_path, period):
    with pytest.raises(BagError, match='flush_period_log_s must be a positive number'):
        BagWriter(tmp_path / 'run', flush_period_log_s=period)
    with pytest.raises(BagError, match='flush_period_s must be a positive number'):
        BagWriter(tmp_path / 'run2', flush_period_s=period)


def test_custom_data_holds_strings_only(tmp_path):
    with pytest.raises(BagError, match='custom_data holds'):
        BagWriter(tmp_path / 'run', custom_data={'runs': 3})


def test_the_stamp_is_read_from_the_cdr_bytes_of_stamped_types():
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64

    from recorder.rosbag2_format import cdr_stamp_ns, starts_with_stamp
    assert starts_with_stamp(STATE_TYPE) and starts_with_stamp('rosgraph_msgs/msg/Clock')
    assert starts_with_stamp('diagnostic_msgs/msg/DiagnosticArray')
    assert not starts_with_stamp('std_msgs/msg/Float64')
    assert not starts_with_stamp('std_msgs/msg/String')
    assert cdr_stamp_ns(state_bytes(37)) == 3_700_000_000
    clock = serialize_message(Clock(clock=Time(sec=12, nanosec=345)))
    assert cdr_stamp_ns(clock) == 12_000_000_345
    assert cdr_stamp_ns(serialize_message(Float64(data=1.0))[:8]) is None  # too short


def test_a_topic_without_a_message_is_left_out_so_that_rosbags_converts_the_bag(tmp_path):
    """The SDK's writer has no channel (so no schema) for a topic without a message; listing it
    in metadata.yaml would leave rosbags without its type."""
    from rosbags.convert import convert
    writer = write_bag(tmp_path / 'run', count=5)
    writer.add_topic('/parameter_events', 'rcl_interfaces/msg/ParameterEvent')
    info = writer.close()
    assert sorted(info.topics) == ['/train/state']
    metadata = yaml.safe_load((tmp_path / 'run' / 'metadata.yaml').read_text())
    assert [t['topic_metadata']['name'] for t in
            metadata['rosbag2_bagfile_information']['topics_with_message_count']] == \
        ['/train/state']
    convert([tmp_path / 'run'], tmp_path / 'converted', dst_storage='mcap', dst_version=9,
            compress=None, compress_mode='file', default_typestore=None, typestore=None,
            exclude_topics=(), include_topics=(), exclude_msgtypes=(), include_msgtypes=())
    assert bag_info(tmp_path / 'converted').topics['/train/state'].message_count == 5
