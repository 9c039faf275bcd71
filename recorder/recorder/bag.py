"""Bags in the rosbag2 MCAP conventions: a folder with ``<name>_0.mcap`` and ``metadata.yaml``.

As rosbag2 Jazzy's MCAP storage plugin writes them: MCAP profile ``ros2``; one schema per type,
encoding ``ros2msg`` with the full definition and its dependencies (:mod:`recorder.definitions`);
message encoding ``cdr`` (the raw bytes as received); each channel carries
``offered_qos_profiles`` (version 9 YAML, named policies, as the publishers offered them) and
``topic_type_hash`` (RIHS01); a ``rosbag2`` metadata record holds the bag's metadata
(``serialized_metadata``) once at the open and once at the close, and ``metadata.yaml``
(version 9) is written beside the file at the close (:mod:`recorder.rosbag2_format`).

The file is written by the Foxglove SDK's MCAP writer (``foxglove.open_mcap``, Rust: no Python
object per message). Two fields of a message record are the writer's, not rosbag2's: the sequence
counts each channel's messages from 1 (rosbag2 writes 0) and the publish time is the log time
(rosbag2 writes the publisher's send time); every reader the suite is tested with ignores both.
A topic without a message has no channel in the file (the writer registers a channel with its
first message), so it is left out of the bag's metadata too (rosbag2 lists it with no message).

Chunks are not compressed unless asked (``zstd`` or ``lz4``), as Jazzy's plugin writes them by
default, and are closed at least every ``flush_period_s`` of wall time and every
``flush_period_log_s`` of log time (simulated time in a lockstep run), so a killed recorder loses
at most about the smaller of the two; ``recover`` turns what a killed recording holds back into a
valid bag, and leaves an intact one alone.
"""

from __future__ import annotations

import atexit
import logging
import os
import re
import shutil
import struct
import time
import weakref
from collections import Counter
from dataclasses import dataclass, field
from operator import itemgetter
from pathlib import Path
from typing import Callable, Iterable, Iterator, NamedTuple, Sequence

import foxglove
import yaml
import zstandard
from foxglove.mcap import MCAPCompression, MCAPWriteOptions, MCAPWriter
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from ato_common.commands import ros_command
from recorder.definitions import DefinitionNotFound, full_definition
from recorder.rosbag2_format import (
    FormatError,
    bag_metadata,
    dump_qos_profiles,
    dump_yaml,
    opening_metadata,
    parse_qos_profiles,
    type_hash,
)

log = logging.getLogger(__name__)


class _SinkErrors(logging.Handler):
    """The SDK's writer reports a failed write (a full disk) as a warning for each message it
    could not write (the first names the operating system's reason), and only that "a write
    failed" when the chunk is closed: the first reason is kept here for the recorder's own error,
    which says it once, and none of the warnings is printed."""

    OS_REASON = re.compile(r'message: "([^"]*)"')

    def __init__(self):
        super().__init__(logging.WARNING)
        self.first = ''

    def emit(self, record: logging.LogRecord) -> None:
        if not self.first:
            found = self.OS_REASON.search(record.getMessage())
            self.first = found.group(1) if found else ''


_sink_errors = _SinkErrors()
_sink_logger = logging.getLogger('foxglove.log_sink_set')
_sink_logger.addHandler(_sink_errors)
_sink_logger.propagate = False
#: the SDK's writers not yet closed: dropped at the interpreter's exit while it can still run
#: their last words (a writer dropped during the interpreter's shutdown aborts the process)
_open_writers: weakref.WeakSet = weakref.WeakSet()
#: a disk with less free space than this is full for the writer (the reason of a failed write
#: the SDK does not name)
FULL_DISK_BYTES = 1 << 20


@atexit.register
def _drop_open_writers() -> None:
    for writer in list(_open_writers):
        writer._writer = None

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
_TOPIC, _LOG_TIME = itemgetter(0), itemgetter(1)
COMPRESSIONS = {'zstd': MCAPCompression.Zstd, 'lz4': MCAPCompression.Lz4, 'none': None}
#: each compression as a chunk record of the file names it
COMPRESSIONS_IN_FILE = {'zstd': 'zstd', 'lz4': 'lz4', 'none': ''}
#: the chunks' compression unless one is asked for: none, as rosbag2 Jazzy's MCAP plugin writes
#: them when neither a storage preset nor a storage config file says otherwise (its writer
#: options start from no compression; ``ros2 bag record --storage-preset-profile zstd_fast``
#: asks for zstd). It is also what costs the loop least: the chunk is written as it is.
#: The chunks' CRCs are kept, where the plugin leaves them out by default: the readers here
#: validate them (``read_messages``), so that damage is an error and not data.
DEFAULT_COMPRESSION = 'none'
#: the compressor's level of each compression (0: the compressor's own default): zstd, when
#: asked for, at level 1 (the mcap library's ``CompressionLevel::Default``, which it maps to
#: zstd level 1), where zstd's own default is 3
COMPRESSION_LEVELS = {'zstd': 1, 'lz4': 0, 'none': 0}


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


def _check_options(compression: str, flush_period_s: float, flush_period_log_s: float,
                   custom_data: dict | None) -> dict[str, str]:
    if compression not in COMPRESSIONS:
        raise BagError(f"compression '{compression}' is not one of {', '.join(COMPRESSIONS)}")
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
    return custom_data


class BagWriter:
    """A bag being written. ``add_topic`` registers a topic (its schema and channel), ``write``
    and ``write_many`` add messages (raw CDR bytes at a log time), ``flush`` closes the open chunk
    (what a SIGKILL cannot take back), ``close`` finishes the file and writes metadata.yaml.
    One thread at a time: the recorder writes from its node's thread (in the composed stack,
    the loop's thread). The SDK's writer holds Python's lock while it writes and compresses."""

    def __init__(self, folder: Path, compression: str = DEFAULT_COMPRESSION,
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_period_s: float = DEFAULT_FLUSH_PERIOD_S,
                 flush_period_log_s: float = DEFAULT_FLUSH_PERIOD_LOG_S,
                 custom_data: dict[str, str] | None = None):
        self.custom_data = _check_options(compression, flush_period_s, flush_period_log_s,
                                          custom_data)
        self.folder = Path(folder)
        if self.folder.exists() and any(self.folder.iterdir()):
            raise BagError(f'{self.folder} exists and is not empty: choose another output folder')
        # A context of its own: the writer records exactly the channels this bag registers.
        self._context = foxglove.Context()
        options = MCAPWriteOptions(profile='ros2', compression=COMPRESSIONS[compression],
                                   compression_level=COMPRESSION_LEVELS[compression],
                                   chunk_size=chunk_size, compression_threads=0)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            self.path = bag_file(self.folder)
            # Created by this writer or not at all (two recorders given one folder at the same
            # moment: the second is refused instead of both writing one file). The SDK opens
            # the file itself: no Python call per write.
            self._writer: MCAPWriter | None = foxglove.open_mcap(
                self.path, allow_overwrite=False, context=self._context, writer_options=options)
        except FileExistsError:
            raise BagError(f'{self.path} was just created by another recorder: choose another '
                           'output folder') from None
        except OSError as error:
            raise BagError(f'cannot create {bag_file(self.folder)}: {_reason(error)}') from None
        _open_writers.add(self)
        _sink_errors.first = ''
        self.flush_period_s = flush_period_s
        self.flush_period_log_ns = int(flush_period_log_s * 1e9)
        self._schemas: dict[str, foxglove.Schema] = {}
        self._channels: dict[str, foxglove.Channel] = {}
        # topic -> its channel's log (the compiled call): (data, log time ns)
        self._log: dict[str, Callable[[bytes, int], None]] = {}
        self.topics: dict[str, TopicInfo] = {}
        self.start_ns: int | None = None
        self.end_ns = 0
        self.closed = False
        self.failed = False
        self.warnings: list[str] = []
        self._last_flush = time.monotonic()
        self._last_flush_log_ns: int | None = None
        self.flushed_ns: int | None = None  # the newest log time on disk (flushed)
        self.flushes = 0  # how often the file was flushed: everything written before is on disk
        # As rosbag2 does: the bag's metadata at the open (no topic yet, the custom data), on
        # disk at once, so that a killed recording keeps its custom data.
        self._write_record(opening_metadata(self.path.name, self.custom_data))
        self.flush()

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
        schema = self._schemas.get(type_name)
        if schema is None:
            definition = ''
            try:
                definition = full_definition(type_name)
            except (DefinitionNotFound, ValueError) as error:
                # Still recorded; readers that need the definition will not decode it.
                warning = f'no message definition for {type_name} ({error}); {topic} is ' \
                          'recorded without one'
                self.warnings.append(warning)
                log.warning(warning)
            schema = self._schemas[type_name] = foxglove.Schema(
                name=type_name, encoding='ros2msg', data=definition.encode())
        if type_description_hash is None:
            type_description_hash = type_hash(type_name, schema.data.decode())
        channel = foxglove.Channel(
            topic, message_encoding='cdr', schema=schema, context=self._context,
            metadata={'offered_qos_profiles': dump_qos_profiles(profiles),
                      'topic_type_hash': type_description_hash})
        self._channels[topic] = channel
        self._log[topic] = channel.base.log
        self.topics[topic] = TopicInfo(topic, type_name, profiles,
                                       type_description_hash=type_description_hash)

    def _failed(self, error: Exception) -> BagError:
        self.failed = True
        reason = _sink_errors.first or _full_disk(self.folder) or _reason(error)
        return BagError(f'cannot write {self.path}: {reason}; the recording stopped. '
                        f'The file holds what was flushed before; it is not a closed bag (no '
                        f'metadata.yaml): {recover_command(self.folder)}')

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Add one message; BagError if the file cannot be written (a full disk)."""
        self.write_many(((topic, log_time_ns, data),))

    def write_many(self, messages: Sequence[tuple[str, int, bytes]]) -> None:
        """Add messages, each (topic, log time ns, data), in order, then close the chunk if a
        flush period has passed; BagError if the file cannot be written (a full disk: the
        writer reports it when the chunk is closed)."""
        if self.failed:
            raise BagError(f'{self.path}: the recording stopped after a write error')
        logs, topics = self._log, self.topics
        for topic, log_time_ns, data in messages:
            logs[topic](data, log_time_ns)
        if not messages:
            return
        for topic, count in Counter(map(_TOPIC, messages)).items():
            topics[topic].message_count += count
        self._wrote(min(map(_LOG_TIME, messages)), max(map(_LOG_TIME, messages)))

    def write_indexed(self, names: Sequence[str],
                      entries: Sequence[tuple[int, int, int, bytes]]) -> None:
        """Add the entries of a bundle of step records (``ato_ros.step_records.read_bundle``:
        the index of the topic in ``names``, log time ns, publish time ns, bytes), in order:
        as ``write_many``, with the writer of each topic looked up once."""
        if self.failed:
            raise BagError(f'{self.path}: the recording stopped after a write error')
        if not entries:
            return
        logs = [self._log[name] for name in names]
        for index, log_time_ns, _, data in entries:
            logs[index](data, log_time_ns)
        topics = self.topics
        for index, count in Counter(map(_TOPIC, entries)).items():
            topics[names[index]].message_count += count
        self._wrote(min(map(_LOG_TIME, entries)), max(map(_LOG_TIME, entries)))

    def log_function(self, topic: str) -> Callable[[bytes, int], None]:
        """The compiled call that adds one message of ``topic`` (a channel of this bag): its
        bytes, its log time ns. What it added is not counted until :meth:`wrote` is told."""
        if self.failed:
            raise BagError(f'{self.path}: the recording stopped after a write error')
        return self._log[topic]

    def wrote(self, counts: dict[str, int], first: int, last: int) -> int:
        """``counts`` messages of each topic were added by :meth:`log_function`'s calls, at
        log times ``first`` to ``last``: counted, and the chunk closed if a flush period has
        passed (BagError if the file cannot be written); returns the log time of the next
        flush by log time."""
        topics = self.topics
        for topic, count in counts.items():
            topics[topic].message_count += count
        self._wrote(first, last)
        assert self._last_flush_log_ns is not None  # set by _wrote
        return self._last_flush_log_ns + self.flush_period_log_ns

    def _wrote(self, first: int, last: int) -> None:
        """Messages from log time ``first`` to ``last`` were added: the bag's span, and the
        chunk closed if a flush period has passed."""
        start = first if self.start_ns is None else min(self.start_ns, first)
        end = self.end_ns = max(self.end_ns, last)
        self.start_ns = start
        if self._last_flush_log_ns is None:
            self._last_flush_log_ns = start
        now = time.monotonic()
        if (now - self._last_flush >= self.flush_period_s
                or end - self._last_flush_log_ns >= self.flush_period_log_ns):
            self.flush(now)

    def flush(self, now: float | None = None) -> None:
        """Close the open chunk and push it to the file (what a SIGKILL cannot take back)."""
        if self.failed or self.closed:
            return
        try:
            self._open_writer().flush()
        except (RuntimeError, OSError) as error:
            raise self._failed(error) from None
        self._last_flush = time.monotonic() if now is None else now
        self.flushes += 1
        if self.start_ns is not None:
            self._last_flush_log_ns = self.flushed_ns = self.end_ns

    def _open_writer(self) -> MCAPWriter:
        """The SDK's writer. Released before the bag was closed (at the interpreter's exit,
        ``_drop_open_writers``), the file cannot be finished: failed, BagError."""
        if self._writer is None:
            self.failed = True
            raise BagError(f'cannot write {self.path}: its writer was released at the '
                           f'interpreter\'s exit; the recording stopped: '
                           f'{recover_command(self.folder)}')
        return self._writer

    def _write_record(self, metadata: dict) -> None:
        try:
            self._open_writer().write_metadata(METADATA_RECORD,
                                               {'serialized_metadata': dump_yaml(metadata)})
        except (RuntimeError, OSError) as error:
            raise self._failed(error) from None

    def close(self) -> BagInfo:
        """Finish the file and write metadata.yaml; after a write error only release the file
        (no metadata.yaml: an unfinished bag must not look valid) and raise BagError."""
        if self.closed:
            return self.info()
        self.closed = True
        if not self.failed:
            try:
                self._write_record(metadata_of(self.info()))
                self._open_writer().close()
            except BagError:
                pass  # failed: said below
            except (RuntimeError, OSError) as error:
                self._failed(error)
        if self.failed:
            try:
                if self._writer is not None:
                    self._writer.close()
            except (RuntimeError, OSError):
                pass  # already failed: the error below says so
            # Dropped now: the SDK's writer must not be dropped (and report its error) while
            # the interpreter shuts down.
            self._writer = None
            raise BagError(f'{self.path} could not be finished after a write error: recover '
                           f'what it holds with: {recover_command(self.folder)}')
        self._writer = None
        _fsync(self.path)
        info = self.info()
        write_metadata(info)
        return info

    def info(self) -> BagInfo:
        """The bag as written so far: the topics with a message (a topic without one has no
        channel in the file, the SDK's writer registering a channel with its first message, and
        readers that take the topics of metadata.yaml need every one's schema)."""
        start = self.start_ns or 0
        return BagInfo(self.path, start, max(self.end_ns, start),
                       {name: t for name, t in self.topics.items() if t.message_count},
                       dict(self.custom_data))


def _fsync(path: Path) -> None:
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def _full_disk(folder: Path) -> str:
    """'No space left on device ...' if the disk of ``folder`` is full, else ''."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return ''
    return f'No space left on device ({free} bytes free)' if free < FULL_DISK_BYTES else ''


def _reason(error: Exception) -> str:
    """What went wrong, without the SDK's prefixes."""
    text = getattr(error, 'strerror', None) or str(error)
    return text.removeprefix('FoxgloveError: ')


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
            reader = make_reader(stream)
            summary = reader.get_summary()
            records = list(reader.iter_metadata()) if summary is not None else []
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
                   _custom_data(file, records))


def topic_of(file: Path, channel: Channel, schema: Schema | None, count: int) -> TopicInfo:
    """A channel's topic: its offered QoS (version 8 or 9) and type hash from its metadata."""
    try:
        profiles = parse_qos_profiles(channel.metadata.get('offered_qos_profiles', ''))
    except FormatError as error:
        raise BagError(f'{file}: the offered_qos_profiles of {channel.topic} are not in the '
                       f'rosbag2 format: {error}') from None
    return TopicInfo(channel.topic, schema.name if schema else '', profiles, count,
                     channel.metadata.get('topic_type_hash', ''), channel.message_encoding)


def _custom_data(file: Path, records: Iterable[Metadata] = ()) -> dict[str, str]:
    """custom_data of the bag: from its metadata.yaml, or else from the last ``rosbag2``
    metadata record of the file that holds it (a killed recording has the one of its open)."""
    found = None
    try:
        data = yaml.safe_load((file.parent / METADATA_FILE).read_text())
        found = data['rosbag2_bagfile_information'].get('custom_data')
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        for record in records:
            if record.name != METADATA_RECORD:
                continue
            try:
                found = yaml.safe_load(record.metadata['serialized_metadata']).get(
                    'custom_data')
            except (KeyError, yaml.YAMLError, AttributeError):
                continue
    return {str(k): str(v) for k, v in found.items()} if isinstance(found, dict) else {}


class Recovered(NamedTuple):
    """What ``recover`` did: the bag's info, the bytes at the end of the damaged file that could
    not be read, and whether the bag was intact (then left as it was: nothing lost, 0 bytes)."""

    info: BagInfo
    lost_bytes: int
    intact: bool


def intact_info(file: Path) -> BagInfo | None:
    """The info of a bag whose file is complete (its summary, every chunk's CRC and every
    message the statistics count read back), else None."""
    try:
        info = bag_info(file)
        read = sum(1 for _ in read_messages(file))
    except BagError:
        return None
    return info if read == info.message_count else None


def _read_damaged(file: Path) -> tuple[dict, dict, list, list, int]:
    """Schemas, channels, messages and ``rosbag2`` metadata records of a damaged MCAP, read in
    file order until the data ends or breaks, and the number of bytes read."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    records: list[Metadata] = []
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
                    elif isinstance(record, Metadata):
                        records.append(record)
                    consumed = stream.tell()
            except READ_ERRORS as error:
                log.info('stopped reading %s: %s', file, error)
    except OSError as error:
        raise BagError(f'{file}: cannot read: {error.strerror}') from None
    return schemas, channels, messages, records, consumed


#: a chunk record's compression (as the file names it) -> the mcap writer's
_CHUNK_COMPRESSIONS = {'': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                       'lz4': CompressionType.LZ4}


def _chunk_compression(file: Path) -> CompressionType:
    """The compression of the first chunk of ``file`` that can be read; the default
    compression's if none can (the recovered file then holds no message anyway)."""
    try:
        with open(file, 'rb') as stream:
            reader = StreamReader(stream, skip_magic=False, emit_chunks=True)
            for record in reader.records:
                if isinstance(record, Chunk):
                    return _CHUNK_COMPRESSIONS.get(record.compression, CompressionType.NONE)
    except READ_ERRORS as error:
        log.info('no chunk of %s could be read: %s', file, error)
    except OSError as error:
        raise BagError(f'{file}: cannot read: {error.strerror}') from None
    return _CHUNK_COMPRESSIONS[COMPRESSIONS_IN_FILE[DEFAULT_COMPRESSION]]


def recover(path: Path) -> Recovered:
    """Rewrite what a damaged (e.g. SIGKILLed) MCAP holds into a valid bag at the same place;
    an intact bag is left alone (its metadata.yaml written if it has none).

    Reads records in file order until the data ends or breaks, writes them to a new file (its
    chunks compressed as the damaged file's: ``_chunk_compression``), and only then moves the
    damaged file aside (as ``.damaged``) and the new one into its place, so a failure half-way
    leaves the original untouched. The custom data (``log_time`` among them) comes from the
    ``rosbag2`` record the recorder wrote at the open.
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
    intact = intact_info(file)
    if intact is not None:
        if not (file.parent / METADATA_FILE).exists() and file == bag_file(file.parent):
            write_metadata(intact)
        return Recovered(intact, 0, True)
    damaged = file.with_name(file.name + '.damaged')
    if damaged.exists():
        raise BagError(f'{damaged} exists already: move it away first')
    schemas, channels, messages, records, consumed = _read_damaged(file)
    try:
        lost = file.stat().st_size - consumed
    except OSError as error:
        raise BagError(f'{file}: cannot read: {error.strerror}') from None
    info = _rewrite(file, schemas, channels, messages, _custom_data(file, records),
                    _chunk_compression(file))
    write_metadata(info)
    return Recovered(info, lost, False)


def _rewrite(file: Path, schemas: dict, channels: dict, messages: list,
             custom_data: dict[str, str], compression: CompressionType) -> BagInfo:
    """The records read from a damaged file written to a new one in chunks of the same
    ``compression``, which then takes its place (the damaged one kept as ``.damaged``)."""
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
            writer = Writer(out, compression=compression)
            writer.start(profile='ros2', library='ato-emulator recorder (recovered)')
            writer.add_metadata(METADATA_RECORD, {'serialized_metadata': dump_yaml(
                opening_metadata(file.name, custom_data))})
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
            info = BagInfo(file, min(times), max(times), topics, custom_data)
            writer.add_metadata(METADATA_RECORD, {'serialized_metadata':
                                                  serialized_metadata(info)})
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
        file.replace(file.with_name(file.name + '.damaged'))
        temporary.replace(file)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise BagError(f'cannot write the recovered bag next to {file}: {error.strerror}; '
                       'the damaged file is unchanged') from None
    return info
