"""Bags in the rosbag2 MCAP conventions: a folder with ``<name>_0.mcap`` and ``metadata.yaml``.

As rosbag2 Jazzy's MCAP storage plugin writes them: MCAP profile ``ros2``; one schema per type,
encoding ``ros2msg`` with the full definition and its dependencies; message encoding ``cdr`` (the
raw bytes as received), sequence 0; each channel carries ``offered_qos_profiles`` (version 9 YAML,
named policies, as the publishers offered them) and ``topic_type_hash`` (RIHS01); at the close a
``rosbag2`` metadata record holds the bag's metadata (``serialized_metadata``) and
``metadata.yaml`` (version 9) is written beside the file (:mod:`recorder.rosbag2_format`).

Chunks are zstd-compressed and closed at least every ``flush_period_s`` of wall time and every
``flush_period_log_s`` of log time (simulated time in a lockstep run), so a killed recorder loses
at most about the smaller of the two; ``recover`` turns what a killed recording holds back into a
valid bag.
"""

from __future__ import annotations

import logging
import os
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Iterator

import yaml
import zstandard
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from ato_common.commands import ros_command
from recorder.definitions import DefinitionNotFound, full_definition
from recorder.rosbag2_format import (
    FormatError,
    bag_metadata,
    dump_qos_profiles,
    dump_yaml,
    parse_qos_profiles,
    type_hash,
)

log = logging.getLogger(__name__)

# What the mcap library and its decompressors raise on damaged data, depending on where the
# damage is.
READ_ERRORS = (McapError, ValueError, EOFError, KeyError, struct.error, zstandard.ZstdError,
               RuntimeError)

METADATA_FILE = 'metadata.yaml'
MCAP_MAGIC = b'\x89MCAP0\r\n'
METADATA_RECORD = 'rosbag2'  # the MCAP metadata record rosbag2 writes its metadata into
DEFAULT_CHUNK_SIZE = 256 * 1024
DEFAULT_FLUSH_PERIOD_S = 0.5
DEFAULT_FLUSH_PERIOD_LOG_S = 0.5


def recover_command(path) -> str:
    """What to type to recover ``path``: ``ros2 run recorder recover ...``, or ``ato run ...``
    where there is no ros2 (ato_common.commands)."""
    return ros_command(f'run recorder recover {path}')


class BagError(RuntimeError):
    """A bag that cannot be read or written; the message says which file and what is wrong."""


@dataclass
class TopicInfo:
    name: str
    type: str
    offered_qos_profiles: list[dict] = field(default_factory=list)  # version 9, named
    message_count: int = 0
    type_description_hash: str = ''
    serialization_format: str = 'cdr'

    def as_metadata(self) -> dict:
        return {'name': self.name, 'type': self.type,
                'serialization_format': self.serialization_format,
                'offered_qos_profiles': self.offered_qos_profiles,
                'type_description_hash': self.type_description_hash,
                'message_count': self.message_count}


@dataclass
class BagInfo:
    path: Path
    start_ns: int
    end_ns: int
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics.values())


def bag_file(folder: Path) -> Path:
    return Path(folder) / f'{Path(folder).name}_0.mcap'


class BagWriter:
    def __init__(self, folder: Path, compression: str = 'zstd',
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_period_s: float = DEFAULT_FLUSH_PERIOD_S,
                 flush_period_log_s: float = DEFAULT_FLUSH_PERIOD_LOG_S,
                 custom_data: dict[str, str] | None = None):
        kinds = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                 'none': CompressionType.NONE}
        if compression not in kinds:
            raise BagError(f"compression '{compression}' is not one of {', '.join(kinds)}")
        for name, period in (('flush_period_s', flush_period_s),
                             ('flush_period_log_s', flush_period_log_s)):
            if not (isinstance(period, (int, float)) and period > 0.0 and period < float('inf')):
                raise BagError(f'{name} must be a positive number of seconds, got {period!r}')
        custom_data = dict(custom_data or {})
        bad = [f'{k!r}: {v!r}' for k, v in custom_data.items()
               if not isinstance(k, str) or not isinstance(v, str) or not k]
        if bad:
            raise BagError(f'custom_data holds non-empty string keys and string values only: '
                           f'{", ".join(bad)}')
        self.custom_data = custom_data
        self.folder = Path(folder)
        if self.folder.exists() and any(self.folder.iterdir()):
            raise BagError(f'{self.folder} exists and is not empty: choose another output folder')
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            self.path = bag_file(self.folder)
            # 'x': created by this writer or not at all (two recorders given one folder at
            # the same moment: the second is refused instead of both writing one file).
            self._file: BinaryIO = open(self.path, 'xb')
        except FileExistsError:
            raise BagError(f'{self.path} was just created by another recorder: choose another '
                           'output folder') from None
        except OSError as error:
            raise BagError(f'cannot create {self.folder}: {error.strerror}') from None
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=kinds[compression])
        self._writer.start(profile='ros2', library='ato-emulator recorder')
        self.flush_period_s = flush_period_s
        self.flush_period_log_ns = int(flush_period_log_s * 1e9)
        self._last_flush = time.monotonic()
        self._last_flush_log_ns: int | None = None
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.topics: dict[str, TopicInfo] = {}
        self.start_ns: int | None = None
        self.end_ns = 0
        self.closed = False
        self.failed = False
        self.warnings: list[str] = []

    def add_topic(self, topic: str, type_name: str, offered_qos_profiles=(),
                  type_description_hash: str | None = None) -> None:
        """A channel for ``topic``: ``offered_qos_profiles`` as its publishers offered them (a
        list of version 9 profiles, or their YAML in either version), and the RIHS01 hash of the
        type (computed by rosbags from the definition when None)."""
        if topic in self._channels:
            return
        try:
            profiles = parse_qos_profiles(list(offered_qos_profiles) if not
                                          isinstance(offered_qos_profiles, str)
                                          else offered_qos_profiles)
        except FormatError as error:
            raise BagError(f'{topic}: offered QoS not in the rosbag2 format: {error}') from None
        definition = ''
        try:
            definition = full_definition(type_name)
        except (DefinitionNotFound, ValueError) as error:
            if type_name not in self._schemas:
                # Still recorded; readers that need the definition will not decode it.
                warning = f'no message definition for {type_name} ({error}); {topic} is ' \
                          'recorded without one'
                self.warnings.append(warning)
                log.warning(warning)
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            schema_id = self._writer.register_schema(type_name, 'ros2msg', definition.encode())
            self._schemas[type_name] = schema_id
        if type_description_hash is None:
            type_description_hash = type_hash(type_name, definition)
        self._channels[topic] = self._writer.register_channel(
            topic, 'cdr', schema_id, {'offered_qos_profiles': dump_qos_profiles(profiles),
                                      'topic_type_hash': type_description_hash})
        self.topics[topic] = TopicInfo(topic, type_name, profiles,
                                       type_description_hash=type_description_hash)

    def _failed(self, error: OSError) -> BagError:
        self.failed = True
        return BagError(f'cannot write {self.path}: {error.strerror}; the recording stopped. '
                        f'The file holds what was flushed before; it is not a closed bag (no '
                        f'metadata.yaml): {recover_command(self.folder)}')

    def write(self, topic: str, log_time_ns: int, data: bytes,
              publish_time_ns: int | None = None) -> None:
        """Add one message; BagError if the file cannot be written (a full disk)."""
        self.write_many(((topic, log_time_ns, data, publish_time_ns),))

    def write_many(self, messages) -> None:
        """Add messages, each (topic, log time ns, data, publish time ns or None: the log
        time), in order, then close the chunk if a flush period has passed; BagError if the
        file cannot be written (a full disk)."""
        if self.failed:
            raise BagError(f'{self.path}: the recording stopped after a write error')
        add, channels, topics = self._writer.add_message, self._channels, self.topics
        start, end = self.start_ns, self.end_ns
        try:
            for topic, log_time_ns, data, publish_time_ns in messages:
                # Sequence 0, as rosbag2 writes it.
                add(channels[topic], log_time=log_time_ns, data=data,
                    publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
                    sequence=0)
                topics[topic].message_count += 1
                if start is None or log_time_ns < start:
                    start = log_time_ns
                if log_time_ns > end:
                    end = log_time_ns
                if self._last_flush_log_ns is None:
                    self._last_flush_log_ns = log_time_ns
        except OSError as error:
            raise self._failed(error) from None
        finally:
            self.start_ns, self.end_ns = start, end
        if self._last_flush_log_ns is None:
            return  # nothing written
        now = time.monotonic()
        if (now - self._last_flush >= self.flush_period_s
                or end - self._last_flush_log_ns >= self.flush_period_log_ns):
            self.flush(now, end)

    def flush(self, now: float | None = None, log_time_ns: int | None = None) -> None:
        """Close the open chunk and push it to the file (what a SIGKILL cannot take back)."""
        if self.failed or self.closed:
            return
        try:
            self._writer.flush()
        except OSError as error:
            raise self._failed(error) from None
        self._last_flush = time.monotonic() if now is None else now
        if log_time_ns is not None or self.topics:
            self._last_flush_log_ns = self.end_ns if log_time_ns is None else log_time_ns

    def close(self) -> BagInfo:
        """Finish the file and write metadata.yaml; after a write error only release the file
        (no metadata.yaml: an unfinished bag must not look valid) and raise BagError."""
        if self.closed:
            return self.info()
        self.closed = True
        if not self.failed:
            try:
                self._writer.add_metadata(METADATA_RECORD, {
                    'serialized_metadata': serialized_metadata(self.info())})
                self._writer.finish()
                self._file.flush()
                os.fsync(self._file.fileno())
            except OSError as error:
                self._failed(error)
        try:
            self._file.close()
        except OSError:
            pass  # already failed: the error below says so
        if self.failed:
            raise BagError(f'{self.path} could not be finished after a write error: recover '
                           f'what it holds with: {recover_command(self.folder)}')
        info = self.info()
        write_metadata(info)
        return info

    def info(self) -> BagInfo:
        start = self.start_ns or 0
        return BagInfo(self.path, start, max(self.end_ns, start), dict(self.topics),
                       dict(self.custom_data))


def metadata_of(info: BagInfo) -> dict:
    """The bag's ``rosbag2_bagfile_information``, as rosbag2 Jazzy writes it."""
    return bag_metadata(start_ns=info.start_ns, end_ns=info.end_ns,
                        relative_path=info.path.name,
                        topics=[t.as_metadata() for t in info.topics.values()],
                        custom_data=info.custom_data)


def serialized_metadata(info: BagInfo) -> str:
    """What the MCAP's ``rosbag2`` metadata record holds under ``serialized_metadata``."""
    return dump_yaml(metadata_of(info))


def write_metadata(info: BagInfo) -> None:
    """metadata.yaml as rosbag2 writes it, so the folder opens as a bag."""
    data = {'rosbag2_bagfile_information': metadata_of(info)}
    target = info.path.parent / METADATA_FILE
    temporary = target.with_suffix('.yaml.tmp')
    temporary.write_text(dump_yaml(data))
    temporary.replace(target)  # never a half-written metadata.yaml


def resolve(path: Path) -> Path:
    """The .mcap of a bag folder, or the file itself."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob('*.mcap'))
        if not files:
            raise BagError(f'{path} holds no .mcap file')
        return files[0]
    if not path.is_file():
        raise BagError(f'{path} does not exist')
    return path


@dataclass(frozen=True)
class BagMessage:
    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    channel: Channel
    schema: Schema | None


def read_messages(path: Path, topics: list[str] | None = None) -> Iterator[BagMessage]:
    """Messages in log-time order from a complete bag; BagError (naming the file and what is
    wrong) for a file that is not MCAP, truncated or corrupt."""
    file = resolve(path)
    try:
        with open(file, 'rb') as stream:
            reader = make_reader(stream, validate_crcs=True)  # damage is an error, not data
            try:
                summary = reader.get_summary()
            except READ_ERRORS as error:
                raise _explain(file, error) from None
            if summary is None:
                raise BagError(f'{file} has no summary section: it was not closed (a killed '
                               f'recording?); recover it with: {recover_command(file)}')
            read = 0
            for schema, channel, message in reader.iter_messages(topics=topics):
                read += 1
                yield BagMessage(channel.topic, schema.name if schema else '', message.log_time,
                                 message.publish_time, message.data, channel, schema)
            # The index can hide damage (a broken chunk may just yield nothing): count.
            expected = sum(count for cid, count in summary.statistics.channel_message_counts
                           .items() if topics is None or summary.channels[cid].topic in topics
                           ) if summary.statistics else read
            if read != expected:
                raise BagError(f'{file} is damaged: {expected - read} of {expected} messages '
                               f'could not be read; recover what it holds with: '
                               f'{recover_command(file)}')
    except BagError:
        raise
    except READ_ERRORS as error:
        raise _explain(file, error) from None
    except OSError as error:
        raise BagError(f'{file}: cannot read: {error.strerror}') from None


def _explain(file: Path, error: Exception) -> BagError:
    try:
        size = file.stat().st_size
        with open(file, 'rb') as stream:
            head = stream.read(8)
    except OSError as os_error:
        return BagError(f'{file}: cannot read: {os_error.strerror}')
    if not head.startswith(b'\x89MCAP'):
        return BagError(f'{file} is not an MCAP file (it does not start with the MCAP magic)')
    return BagError(f'{file} ({size} bytes) is truncated or corrupt: {type(error).__name__}: '
                    f'{error}; recover what it holds with: {recover_command(file)}')


def bag_info(path: Path) -> BagInfo:
    file = resolve(path)
    try:
        with open(file, 'rb') as stream:
            summary = make_reader(stream).get_summary()
    except READ_ERRORS as error:
        raise _explain(file, error) from None
    if summary is None or summary.statistics is None:
        raise BagError(f'{file} has no summary: it was not closed; recover it with: '
                       f'{recover_command(file)}')
    stats = summary.statistics
    topics = {channel.topic: topic_of(file, channel, summary.schemas.get(channel.schema_id),
                                      stats.channel_message_counts.get(channel_id, 0))
              for channel_id, channel in summary.channels.items()}
    return BagInfo(file, stats.message_start_time, stats.message_end_time, topics,
                   _custom_data(file))


def topic_of(file: Path, channel: Channel, schema: Schema | None, count: int) -> TopicInfo:
    """A channel's topic: its offered QoS (version 8 or 9) and type hash from its metadata."""
    try:
        profiles = parse_qos_profiles(channel.metadata.get('offered_qos_profiles', ''))
    except FormatError as error:
        raise BagError(f'{file}: the offered_qos_profiles of {channel.topic} are not in the '
                       f'rosbag2 format: {error}') from None
    return TopicInfo(channel.topic, schema.name if schema else '', profiles, count,
                     channel.metadata.get('topic_type_hash', ''), channel.message_encoding)


def _custom_data(file: Path) -> dict[str, str]:
    """custom_data of the bag's metadata.yaml, if the folder has one that holds it."""
    metadata = file.parent / METADATA_FILE
    try:
        data = yaml.safe_load(metadata.read_text())
        custom = data['rosbag2_bagfile_information'].get('custom_data') or {}
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return {}
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def recover(path: Path) -> tuple[BagInfo, int]:
    """Rewrite what a damaged (e.g. SIGKILLed) MCAP holds into a valid bag at the same place.

    Reads records in file order until the data ends or breaks, writes them to a new file, and
    only then moves the damaged file aside (as ``.damaged``) and the new one into its place, so a
    failure half-way leaves the original untouched. Returns the new bag's info and the number of
    bytes that could not be read.
    """
    file = resolve(path)
    try:
        with open(file, 'rb') as stream:
            head = stream.read(len(MCAP_MAGIC))
    except OSError as error:
        raise BagError(f'{file}: cannot read: {error.strerror}') from None
    if head != MCAP_MAGIC:
        raise BagError(f'{file} is not an MCAP file (it does not start with the MCAP magic); '
                       'there is nothing to recover and it was left untouched')
    damaged = file.with_name(file.name + '.damaged')
    if damaged.exists():
        raise BagError(f'{damaged} exists already: move it away first')
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    consumed = 0
    try:
        with open(file, 'rb') as stream:
            reader = StreamReader(stream, skip_magic=False, emit_chunks=False)
            try:
                for record in reader.records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        channels[record.id] = record
                    elif isinstance(record, Message):
                        messages.append(record)
                    consumed = stream.tell()
            except READ_ERRORS as error:
                log.info('stopped reading %s: %s', file, error)
        lost = file.stat().st_size - consumed
    except OSError as error:
        raise BagError(f'{file}: cannot read: {error.strerror}') from None
    temporary = file.with_name(file.name + '.recovering')
    counts: dict[int, int] = {}
    times = [m.log_time for m in messages] or [0]
    try:
        topics = {c.topic: topic_of(file, c, schemas.get(c.schema_id), 0)
                  for c in channels.values()}
    except BagError:
        topics = {c.topic: TopicInfo(c.topic, schemas[c.schema_id].name if c.schema_id in
                                     schemas else '') for c in channels.values()}
    try:
        with open(temporary, 'wb') as out:
            writer = Writer(out, compression=CompressionType.ZSTD)
            writer.start(profile='ros2', library='ato-emulator recorder (recovered)')
            schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data)
                          for sid, s in schemas.items()}
            channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding,
                                                        schema_ids.get(c.schema_id, 0),
                                                        c.metadata)
                           for cid, c in channels.items()}
            for m in sorted(messages, key=lambda m: m.log_time):
                if m.channel_id in channel_ids:
                    writer.add_message(channel_ids[m.channel_id], m.log_time, m.data,
                                       m.publish_time, m.sequence)
                    counts[m.channel_id] = counts.get(m.channel_id, 0) + 1
            for cid, c in channels.items():
                topics[c.topic].message_count = counts.get(cid, 0)
            info = BagInfo(file, min(times), max(times), topics, _custom_data(file))
            writer.add_metadata(METADATA_RECORD, {'serialized_metadata':
                                                  serialized_metadata(info)})
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
        file.replace(damaged)
        temporary.replace(file)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise BagError(f'cannot write the recovered bag next to {file}: {error.strerror}; '
                       'the damaged file is unchanged') from None
    write_metadata(info)
    return info, lost
