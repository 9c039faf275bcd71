"""Step records: what a loop node publishes per step, bundled for the recorders.

Recording a lockstep run topic by topic costs the loop a publish of every observation topic
(the truth, the actuator forces, the distance to go, the permitted speed) that nobody else
reads, and the recorder a take of each of the nine per-step topics at every step, each a
fixed cost in rclpy and the middleware that dwarfs the message's own (``make bench`` measures
what recording costs). Instead, each loop node that a recorder subscribes to adds the bytes of every
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

A recorder acknowledges what it has written of a namespace's step records on ``recorded`` (a
``std_msgs/msg/Header``: the stamp up to which every record of the namespace is in its file,
flushed; ``frame_id`` its node name) once that has moved on by ``ACK_PERIOD_S`` (``Written``).
In lockstep the plant does not publish a step more than its lead (``LEAD_S`` by default) past
the oldest acknowledgement of the recorders in the graph (``Acknowledgements``;
``ato_ros.publishing.RecorderLead``): back-pressure, so that a recorder starved of CPU holds the
loop instead of falling behind it, and a SIGKILL loses at most the lead.
"""

from __future__ import annotations

import struct
import time

from ato_common.conventions import STEP_RECORDED, TOPICS
from ato_ros.wire import MessageError

#: a bundle is published once its entries span this much of the node's stamps, s (fewer
#: bundles cost the loop and the recorder less, a publish and a take each; what a node holds is
#: lost with a SIGKILLed recorder, which the recorder's lead bounds: LEAD_S)
PERIOD_S = 0.8
#: ... or once its first entry is this old in wall time (a real-time run), s
WALL_PERIOD_S = 0.05
#: a recorder acknowledges a namespace's step records (topic ``recorded``) once the oldest of
#: what it has written of them has advanced by this much since its last acknowledgement, s of
#: their stamps; it flushes its file before each (a publish and a flush for the recorder, a take
#: for the plant: fewer of them cost less, for a longer lead)
ACK_PERIOD_S = 0.6
#: in lockstep the plant runs at most this far past the oldest acknowledgement of the recorders
#: that acknowledge (back-pressure: ``ato_ros.publishing.RecorderLead``), s of simulated time: what
#: a SIGKILLed recorder can lose (docs/guide/recording.md; the plant's recorder_lead_s). A
#: control period over the least lead at 10 Hz (``least_lead_s``), so that a recorder that
#: keeps up never holds the loop.
LEAD_S = 1.7


def least_lead_s(control_period_s: float) -> float:
    """The least lead that cannot stall a lockstep loop whose recorder keeps up. With the plant
    held before publishing step s, every node has published its records up to s - 2 control
    periods at the latest (the controller answers a step after the plant and the profile),
    less its bundle in the making (under ``PERIOD_S`` of stamps); the recorder acknowledges
    once the oldest of them has advanced by ``ACK_PERIOD_S``. A lead under this sum would wait
    for records that no node sends before the plant's next step."""
    return PERIOD_S + ACK_PERIOD_S + 2.0 * control_period_s


ENTRY = struct.Struct('<IIqq')
_U32 = struct.Struct('<I')
_HEADER = b'\x00\x01\x00\x00'  # CDR_LE: as ato_ros.wire writes


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
    names, entries = read_bundle(data)
    return [(names[index], log_ns, publish_ns, message)
            for index, log_ns, publish_ns, message in entries]


def read_bundle(data: bytes) -> tuple[list[str], list[tuple[int, int, int, bytes]]]:
    """The topics a bundle names and its entries, (index of the topic, log time ns, publish
    time ns, message bytes), in the order they were published: a recorder writes them with a
    writer per topic looked up once per bundle. MessageError names what does not hold."""
    if data[:4] != _HEADER:
        raise MessageError(f'step records: encapsulation {data[:4].hex()} is not the CDR_LE '
                           'the loop nodes write')
    data = bytes(data)
    try:
        (count,), at = _U32.unpack_from(data, 4), 8
        names, sizes = [], []
        for _ in range(count):
            (length,) = _U32.unpack_from(data, at)
            at += 4
            names.append(data[at:at + length - 1].decode())
            at += length + (-length % 4)
            size, _stride = struct.unpack_from('<II', data, at)
            sizes.append(size)
            at += 8
        (offset,), (length,) = _U32.unpack_from(data, at), _U32.unpack_from(data, at + 4)
        at += 8
    except (struct.error, UnicodeDecodeError) as error:
        raise MessageError(f'step records: the layout does not parse ({error})') from None
    end = at + length
    if offset != 0 or end > len(data):
        raise MessageError(f'step records: data_offset {offset}, {length} bytes of data where '
                           f'{len(data) - at} remain')
    entries: list[tuple[int, int, int, bytes]] = []
    append, unpack, topics, seen = entries.append, ENTRY.unpack_from, len(names), [0] * len(names)
    while at < end:
        if at + ENTRY.size > end:
            raise MessageError(f'step records: {end - at} bytes left where an entry header '
                               'needs 24')
        index, size, log_ns, publish_ns = unpack(data, at)
        at += ENTRY.size
        if index >= topics or at + size > end:
            raise MessageError(f'step records: entry of topic {index} of {topics} and '
                               f'{size} bytes where {end - at} remain')
        append((index, log_ns, publish_ns, data[at:at + size]))
        seen[index] += 1
        at += size + (-size % 8)
    if seen != sizes:
        raise MessageError(f'step records: the layout counts {sizes} messages per topic, the '
                           f'data holds {seen}')
    return names, entries


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
    ``ato_ros.publishing.StepRecorder``): ``add`` appends a message the node published (or, for an
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
        """Whether the bundle spans ``period_s`` of stamps at ``stamp_ns``, or is stale."""
        return self.first_ns is not None and (
            stamp_ns - self.first_ns >= self.period_ns or self.stale())

    def stale(self) -> bool:
        """Whether the bundle in the making is due by wall time alone (what a step that
        comes finds too; with none coming, a loop held or ticks that stopped, the node's timer
        asks, ``ato_ros.publishing.StepRecorder.send_stale``)."""
        return self.first_ns is not None and \
            time.monotonic() - self.first_wall >= self.wall_period_s

    def take(self) -> bytes | None:
        """The serialised bundle (None if empty), and a new one begun."""
        if not self.names:
            return None
        data = encode_bundle(self.names, self.counts, bytes(self.body))
        self.clear()
        return data


class Written:
    """What a recorder has written of one namespace's step records: the stamp of the latest
    entry of each topic. The namespace's records are in the file up to the oldest of these
    (``on_disk_ns``) once the file is flushed; ``acknowledgement`` says when that has moved by
    ``ACK_PERIOD_S`` (or back: a restarted plant begins its time again) since the last one.

    The oldest of the topics written so far vouches only for those topics: the first
    acknowledgement waits until a bundle of every publisher of the namespace's step records
    (``publishers``, as the graph counts them) is written, or an acknowledgement made when
    only the profile's bundles had come would let the plant run a lead past a file without its
    state. A bundle's topics are one publisher's (each per-step topic has one publisher), so
    the publishers heard from are the groups of topics that came in a bundle together
    (``bundled``)."""

    def __init__(self, period_s: float = ACK_PERIOD_S):
        self.period_ns = int(round(period_s * 1e9))
        self.latest: dict[str, int] = {}
        self.acknowledged: int | None = None
        self.flushed_ns: int | None = None  # on_disk_ns() when the file was last flushed
        self.publishers = 0  # how many publish the step records (the graph's count)
        self._group: dict[str, str] = {}  # topic -> a topic of its publisher's bundles

    def wrote(self, topic: str, stamp_ns: int) -> None:
        self.latest[topic] = stamp_ns

    def bundled(self, topics) -> None:
        """A bundle of ``topics`` is written (noted until the first acknowledgement)."""
        if self.acknowledged is not None:
            return
        roots = {self._root(topic) for topic in topics}
        if roots:
            first = roots.pop()
            for root in roots:
                self._group[root] = first

    def _root(self, topic: str) -> str:
        group = self._group
        while group.setdefault(topic, topic) != topic:
            topic = group[topic]
        return topic

    def heard_from(self) -> int:
        """How many publishers' bundles are written (before the first acknowledgement)."""
        return len({self._root(topic) for topic in list(self._group)})

    def on_disk_ns(self) -> int | None:
        return min(self.latest.values()) if self.latest else None

    def flushed(self) -> None:
        """The file was flushed: everything written so far is on disk."""
        self.flushed_ns = self.on_disk_ns()

    def needs_flush(self, stamp_ns: int) -> bool:
        """Whether the file must be flushed before ``stamp_ns`` is acknowledged (not if a
        flush since the records up to it were written put them on disk already)."""
        return self.flushed_ns is None or stamp_ns > self.flushed_ns

    def acknowledgement(self) -> int | None:
        """The stamp to acknowledge now (then counted as acknowledged), else None."""
        stamp = self.on_disk_ns()
        if stamp is None or (self.acknowledged is not None
                             and 0 <= stamp - self.acknowledged < self.period_ns):
            return None
        if self.acknowledged is None and self.heard_from() < self.publishers:
            return None  # a publisher's records are not in the file yet
        self.acknowledged = stamp
        return stamp


class Acknowledgements:
    """The plant's side of the recorders' acknowledgements (topic ``recorded``; the rclpy side
    is ``ato_ros.publishing.RecorderLead``): the latest stamp each recorder has acknowledged, and
    whether a step is more than ``lead_ns`` past the oldest of them. A recorder seen in the graph
    before it has acknowledged anything counts as having acknowledged the step at which it was
    seen (``appeared``): one that stops before its first acknowledgement holds the loop too.
    ``heard`` holds the recorders that have acknowledged something (the others' stamps say
    when they were seen, not what their files hold)."""

    def __init__(self, lead_ns: int):
        self.lead_ns = lead_ns
        self.stamps: dict[str, int] = {}  # recorder's node name -> stamp acknowledged
        self.heard: set[str] = set()

    def acknowledged(self, recorder: str, stamp_ns: int) -> None:
        self.stamps[recorder] = stamp_ns
        self.heard.add(recorder)

    def appeared(self, recorder: str, stamp_ns: int) -> None:
        """``recorder`` is in the graph at the step ``stamp_ns`` (nothing changes for one
        already known)."""
        self.stamps.setdefault(recorder, stamp_ns)

    def behind(self, stamp_ns: int) -> tuple[str, int] | None:
        """(recorder, stamp it acknowledged) of the oldest recorder if ``stamp_ns`` is more
        than the lead past it, else None."""
        if not self.stamps:
            return None
        recorder = min(self.stamps, key=self.stamps.__getitem__)
        acknowledged = self.stamps[recorder]
        return (recorder, acknowledged) if stamp_ns - acknowledged > self.lead_ns else None

    def keep(self, live: set[str]) -> None:
        """Forget the recorders not in ``live`` (gone from the graph)."""
        for recorder in [r for r in self.stamps if r not in live]:
            del self.stamps[recorder]
            self.heard.discard(recorder)
