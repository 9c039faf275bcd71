"""Step records: what a loop node publishes per step, bundled for the recorders.

Recording a lockstep run topic by topic costs the loop a publish of every observation topic
(the truth, the actuator forces, the distance to go, the permitted speed) that nobody else
reads, and the recorder a take of each of the nine per-step topics at every step: on a 2-core
machine about 0.1 ms of CPU per publish or take in rclpy, which made a recorded run about a
third slower. Instead, each loop node that a recorder subscribes to adds the bytes of every
per-step message it publishes (``conventions.STEP_RECORDED``; the observation topics whether
or not anybody subscribes to them) to a bundle, and publishes the bundle on ``step_records``
once it spans ``PERIOD_S`` of its stamps or ``WALL_PERIOD_S`` of wall time, and before it
exits. The recorder (``recorder.node``) takes the bundles and writes each message under its
own topic, at its own log time, as if it had subscribed to it: the bag is the same.

On the wire a bundle is a standard ``std_msgs/msg/UInt8MultiArray``: ``layout.dim`` names
the topics it holds (``label``: the topic's full name, ``size``: how many of its messages,
``stride`` 0), ``layout.data_offset`` is 0 and ``data`` is the messages one after the other,
each an entry header ``ENTRY`` (little-endian: uint32 index into ``layout.dim``, uint32 length,
int64 log time ns, int64 publish time ns) followed by the message's serialised bytes (CDR with
its encapsulation header, as published) and zeros up to a multiple of 8 bytes. The log time
is the step's stamp (simulated time in lockstep), the publish time the node's wall clock when
it published the message.
"""

from __future__ import annotations

import struct
import time

from ato_common.conventions import STEP_RECORDED, TOPICS
from ato_common.wire import MessageError

#: a bundle is published once its entries span this much of the node's stamps, s (what a node
#: holds is lost with a SIGKILLed recorder: this keeps a SIGKILL in lockstep within the 1 s of
#: simulated time that docs/guide/recording.md promises, tests/test_recording_jazzy.py)
PERIOD_S = 0.2
#: ... or once its first entry is this old in wall time (a real-time run), s
WALL_PERIOD_S = 0.05

ENTRY = struct.Struct('<IIqq')
_U32 = struct.Struct('<I')
_HEADER = b'\x00\x01\x00\x00'  # CDR_LE: as ato_common.wire writes


def _padding(length: int, alignment: int) -> bytes:
    return b'\x00' * (-length % alignment)


def encode_bundle(names: list[str], counts: list[int], body: bytes) -> bytes:
    """The serialised ``std_msgs/msg/UInt8MultiArray`` of a bundle (module docstring)."""
    parts = [_HEADER, _U32.pack(len(names))]
    for name, count in zip(names, counts):
        label = name.encode() + b'\x00'
        parts += [_U32.pack(len(label)), label, _padding(len(label), 4),
                  struct.pack('<II', count, 0)]
    parts += [_U32.pack(0), _U32.pack(len(body)), body]
    return b''.join(parts)


def decode_bundle(data: bytes) -> list[tuple[str, int, int, bytes]]:
    """The entries of a bundle: (topic, log time ns, publish time ns, message bytes) in the
    order they were published. MessageError names what does not hold."""
    if data[:4] != _HEADER:
        raise MessageError(f'step records: encapsulation {data[:4].hex()} is not the CDR_LE '
                           'the loop nodes write')
    view = memoryview(data)[4:]
    try:
        (count,), at = _U32.unpack_from(view, 0), 4
        names, sizes = [], []
        for _ in range(count):
            (length,) = _U32.unpack_from(view, at)
            at += 4
            names.append(bytes(view[at:at + length - 1]).decode())
            at += length + (-length % 4)
            size, _stride = struct.unpack_from('<II', view, at)
            sizes.append(size)
            at += 8
        (offset,), (length,) = _U32.unpack_from(view, at), _U32.unpack_from(view, at + 4)
        at += 8
    except (struct.error, UnicodeDecodeError) as error:
        raise MessageError(f'step records: the layout does not parse ({error})') from None
    if offset != 0 or at + length > len(view):
        raise MessageError(f'step records: data_offset {offset}, {length} bytes of data where '
                           f'{len(view) - at} remain')
    body = view[at:at + length]
    entries, at, seen = [], 0, [0] * len(names)
    while at < length:
        if at + ENTRY.size > length:
            raise MessageError(f'step records: {length - at} bytes left where an entry header '
                               'needs 24')
        index, size, log_ns, publish_ns = ENTRY.unpack_from(body, at)
        at += ENTRY.size
        if index >= len(names) or at + size > length:
            raise MessageError(f'step records: entry of topic {index} of {len(names)} and '
                               f'{size} bytes where {length - at} remain')
        entries.append((names[index], log_ns, publish_ns, bytes(body[at:at + size])))
        seen[index] += 1
        at += size + (-size % 8)
    if seen != sizes:
        raise MessageError(f'step records: the layout counts {sizes} messages per topic, the '
                           f'data holds {seen}')
    return entries


def namespace_of(topic: str, key: str) -> str | None:
    """The namespace ('/' the root) in which ``topic`` is the conventions' topic ``key`` (a
    stack in a namespace has its /clock there too: conventions.stack_remaps), else None."""
    name = TOPICS[key].name.lstrip('/')
    if topic == '/' + name:
        return '/'
    if topic.endswith('/' + name):
        return topic[:-len(name) - 1]
    return None


def step_recorded(topic: str) -> tuple[str, str] | None:
    """(key, namespace) if ``topic`` is one of the per-step topics the step records carry
    (conventions.STEP_RECORDED), in any namespace, else None."""
    for key in STEP_RECORDED:
        namespace = namespace_of(topic, key)
        if namespace is not None:
            return key, namespace
    return None


class Bundle:
    """A node's bundle in the making (the rclpy side, which publishes it, is
    ``ato_common.ros.StepRecorder``): ``add`` appends a message the node published (or, for an
    observation topic nobody subscribes to, would have), ``due`` says when the bundle spans
    ``period_s`` of stamps or its first entry is ``wall_period_s`` old, ``take`` returns the
    serialised bundle and starts a new one."""

    def __init__(self, period_s: float = PERIOD_S, wall_period_s: float = WALL_PERIOD_S):
        self.period_ns = int(round(period_s * 1e9))
        self.wall_period_s = wall_period_s
        self.clear()

    def clear(self) -> None:
        self.index: dict[str, int] = {}
        self.names: list[str] = []
        self.counts: list[int] = []
        self.body = bytearray()
        self.first_ns: int | None = None
        self.first_wall = 0.0

    def __len__(self) -> int:
        return len(self.body)  # 0: empty

    def add(self, topic_name: str, log_time_ns: int, data: bytes) -> None:
        index = self.index.get(topic_name)
        if index is None:
            index = self.index[topic_name] = len(self.names)
            self.names.append(topic_name)
            self.counts.append(0)
        self.counts[index] += 1
        if self.first_ns is None:
            self.first_ns, self.first_wall = log_time_ns, time.monotonic()
        body = self.body
        body += ENTRY.pack(index, len(data), log_time_ns, time.time_ns())
        body += data
        body += _padding(len(data), 8)

    def due(self, stamp_ns: int) -> bool:
        return self.first_ns is not None and (
            stamp_ns - self.first_ns >= self.period_ns
            or time.monotonic() - self.first_wall >= self.wall_period_s)

    def take(self) -> bytes | None:
        """The serialised bundle (None if empty), and a new one begun."""
        if not self.names:
            return None
        data = encode_bundle(self.names, self.counts, bytes(self.body))
        self.clear()
        return data
