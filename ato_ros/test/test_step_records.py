"""A bundle of step records is a standard std_msgs/msg/UInt8MultiArray (checked against rclpy's
own serialisation both ways), holds every message added, in order, with its topic and times,
and a damaged one is refused with the reason. A recorder acknowledges what it has written of a
namespace's records, and the plant's lead is measured from the oldest acknowledgement."""

import random
import struct

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray

from ato_common.conventions import STEP_RECORDED, TOPICS
from ato_ros import wire
from ato_ros.step_records import (
    ACK_PERIOD_S,
    ENTRY,
    LEAD_S,
    PERIOD_S,
    Acknowledgements,
    Bundle,
    Written,
    decode_bundle,
    encode_bundle,
    least_lead_s,
    step_recorded,
)
from ato_ros.wire import MessageError

rng = random.Random(20261202)


def _bundle(entries) -> bytes:
    bundle = Bundle(period_s=1e9, wall_period_s=1e9)
    for topic, stamp, data in entries:
        bundle.add(topic, stamp, data)
    return bundle.take()


def _entries(count: int):
    topics = ['/clock', '/train/state', '/ns/ato/reference', '/ato/distance_to_go']
    return [(rng.choice(topics), rng.randrange(0, 10**12),
             bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40))))
            for _ in range(count)]


@pytest.mark.parametrize('count', [1, 2, 7, 50])
def test_a_bundle_is_a_standard_uint8_multiarray_naming_its_topics(count):
    entries = _entries(count)
    data = _bundle(entries)
    msg = deserialize_message(data, UInt8MultiArray)
    names = list(dict.fromkeys(topic for topic, _, _ in entries))
    assert [d.label for d in msg.layout.dim] == names
    assert [d.size for d in msg.layout.dim] == [sum(t == n for t, _, _ in entries)
                                                for n in names]
    assert msg.layout.data_offset == 0
    decoded = decode_bundle(data)
    assert [(t, log, d) for t, log, _, d in decoded] == entries
    # rclpy's own serialisation of that message (its padding undefined) reads the same
    assert decode_bundle(serialize_message(msg)) == decoded


def test_an_entry_keeps_the_log_time_given_and_the_wall_time_it_was_added():
    import time
    before = time.time_ns()
    data = _bundle([('/clock', 42, wire.encode_clock(42))])
    ((topic, log_ns, publish_ns, message),) = decode_bundle(data)
    assert (topic, log_ns, message) == ('/clock', 42, wire.encode_clock(42))
    assert before <= publish_ns <= time.time_ns()


def test_a_bundle_is_due_after_its_period_of_stamps_and_take_starts_a_new_one():
    bundle = Bundle(period_s=0.2, wall_period_s=1e9)
    assert not bundle.due(0) and bundle.take() is None and not len(bundle)
    bundle.add('/clock', 100_000_000, b'\x00\x01\x00\x00')
    assert not bundle.due(200_000_000)
    assert bundle.due(300_000_000)
    assert len(decode_bundle(bundle.take())) == 1
    assert not len(bundle) and bundle.take() is None


def test_a_bundle_is_due_after_its_wall_period():
    bundle = Bundle(period_s=1e9, wall_period_s=0.0)
    bundle.add('/clock', 0, b'')
    assert bundle.due(0)


def test_rclpy_s_own_message_decodes_as_long_as_it_follows_the_layout():
    body = ENTRY.pack(0, 3, 5, 6) + b'abc' + b'\x00' * 5
    msg = UInt8MultiArray()
    msg.layout.dim = [MultiArrayDimension(label='/train/state', size=1, stride=0)]
    msg.data = list(body)
    assert decode_bundle(serialize_message(msg)) == [('/train/state', 5, 6, b'abc')]


@pytest.mark.parametrize('damage, reason', [
    (lambda d: b'\x00\x00' + d[2:], 'encapsulation'),
    (lambda d: d[:-5], 'remain'),
    (lambda d: d[:8], 'does not parse'),
])
def test_a_damaged_bundle_is_refused_with_the_reason(damage, reason):
    data = _bundle(_entries(3))
    with pytest.raises(MessageError, match=reason):
        decode_bundle(damage(data))


def test_counts_that_disagree_with_the_data_are_refused():
    body = ENTRY.pack(0, 0, 1, 2)
    data = encode_bundle(['/clock'], [2], body)
    with pytest.raises(MessageError, match=r'counts \[2\].*holds \[1\]'):
        decode_bundle(data)


def test_an_entry_pointing_past_the_topics_is_refused():
    data = encode_bundle(['/clock'], [1], ENTRY.pack(3, 0, 1, 2))
    with pytest.raises(MessageError, match='topic 3 of 1'):
        decode_bundle(data)


def test_the_per_step_topics_are_found_in_any_namespace():
    for key in STEP_RECORDED:
        name = TOPICS[key].name
        assert step_recorded('/' + name.lstrip('/')) == (key, '/')
        assert step_recorded('/train1/' + name.lstrip('/')) == (key, '/train1')
    assert step_recorded('/diagnostics') is None
    assert step_recorded('/ato/reference/curve') is None


def test_the_entry_header_is_24_bytes_little_endian():
    assert ENTRY.size == 24 and ENTRY.format == '<IIqq'
    assert struct.calcsize(ENTRY.format) == 24


# --- acknowledgements and the plant's lead (back-pressure in lockstep) --------------------------

S = 1_000_000_000


def test_a_namespace_is_on_disk_up_to_the_oldest_topic_written():
    written = Written()
    assert written.on_disk_ns() is None and written.acknowledgement() is None
    written.wrote('/clock', 5 * S)
    written.wrote('/ato/command', 4 * S)
    assert written.on_disk_ns() == 4 * S
    written.wrote('/ato/command', 6 * S)
    assert written.on_disk_ns() == 5 * S


def test_an_acknowledgement_comes_once_the_oldest_moved_on_by_its_period():
    written = Written(period_s=0.2)
    written.wrote('/clock', 1 * S)
    assert written.acknowledgement() == 1 * S  # the first
    written.wrote('/clock', 1 * S + 150_000_000)
    assert written.acknowledgement() is None  # 0.15 s on: not yet
    written.wrote('/clock', 1 * S + 200_000_000)
    assert written.acknowledgement() == 1 * S + 200_000_000
    assert written.acknowledgement() is None  # said once
    written.wrote('/clock', 100_000_000)  # a restarted plant begins its time again
    assert written.acknowledgement() == 100_000_000


def test_the_first_acknowledgement_waits_for_a_bundle_of_every_publisher():
    """Issue 31: the profile's bundles come first; an acknowledgement of them alone would
    vouch for a file without the plant's state. The first waits until every publisher of the
    step records (the graph's count) has a bundle written; later ones do not ask again."""
    written = Written(period_s=0.2)
    written.publishers = 3
    profile = ('/ato/reference', '/ato/distance_to_go', '/ato/permitted_speed')
    for k in range(5):
        for topic in profile:
            written.wrote(topic, k * S)
        written.bundled(profile[:1 + k % 3])  # one publisher's topics, not always all
        assert written.acknowledgement() is None, k
    written.wrote('/ato/command', 2 * S)
    written.bundled(['/ato/command'])
    assert written.acknowledgement() is None  # the plant's state is not in the file yet
    written.wrote('/train/state', 3 * S)
    written.wrote('/clock', 3 * S)
    written.bundled(['/train/state', '/clock'])
    assert written.acknowledgement() == 2 * S
    written.publishers = 4  # a publisher joining later holds nothing
    written.wrote('/ato/command', 5 * S)
    assert written.acknowledgement() == 3 * S


def test_an_acknowledgement_asks_for_a_flush_unless_one_came_after_its_records():
    written = Written(period_s=0.2)
    written.wrote('/clock', 1 * S)
    assert written.needs_flush(1 * S)  # never flushed
    written.flushed()  # e.g. the writer closed its chunk at the end of a write
    assert not written.needs_flush(1 * S)
    written.wrote('/clock', 2 * S)
    assert written.needs_flush(2 * S) and not written.needs_flush(1 * S)


def test_the_plant_is_held_past_the_lead_of_the_oldest_recorder_only():
    acks = Acknowledgements(lead_ns=900_000_000)
    assert acks.behind(100 * S) is None  # nobody acknowledges: nothing held
    acks.acknowledged('/recorder', 10 * S)
    acks.acknowledged('/other', 9 * S)
    assert acks.behind(9 * S + 900_000_000) is None  # exactly the lead: goes
    assert acks.behind(9 * S + 900_000_001) == ('/other', 9 * S)
    acks.keep({'/recorder'})  # /other left the graph
    assert acks.behind(9 * S + 900_000_001) is None
    assert acks.behind(10 * S + 900_000_001) == ('/recorder', 10 * S)
    acks.keep(set())
    assert acks.behind(10**6 * S) is None and acks.heard == set()


def test_a_recorder_seen_before_its_first_acknowledgement_holds_from_that_step():
    acks = Acknowledgements(lead_ns=900_000_000)
    acks.appeared('/recorder', 3 * S)
    assert acks.behind(3 * S + 900_000_000) is None
    assert acks.behind(4 * S) == ('/recorder', 3 * S)  # stopped before it said anything
    acks.appeared('/recorder', 8 * S)  # seen again: still what it was
    assert acks.behind(4 * S) == ('/recorder', 3 * S)
    assert acks.heard == set()  # its stamp says when it was seen, not what its file holds
    acks.acknowledged('/recorder', 5 * S)
    assert acks.heard == {'/recorder'}
    assert acks.behind(5 * S + 900_000_000) is None


@pytest.mark.parametrize('rate_hz', [1.0, 10.0, 200.0])
def test_the_least_lead_covers_a_bundle_an_acknowledgement_and_two_steps(rate_hz):
    period = 1.0 / rate_hz
    assert least_lead_s(period) == pytest.approx(PERIOD_S + ACK_PERIOD_S + 2 * period)
    # the default fits the suite's 10 Hz scenarios, with a control period to spare: a recorder
    # that keeps up never holds the loop
    assert LEAD_S >= least_lead_s(0.1) + 0.1 - 1e-9


def test_an_acknowledgement_is_a_standard_header():
    from std_msgs.msg import Header
    data = wire.encode_header(12 * S + 5, '/ns/recorder')
    msg = deserialize_message(data, Header)
    assert (msg.stamp.sec, msg.stamp.nanosec, msg.frame_id) == (12, 5, '/ns/recorder')
    assert wire.decode_header(serialize_message(msg)) == (12 * S + 5, '/ns/recorder')
    with pytest.raises(MessageError):
        wire.decode_header(data[:10])


class _Publisher:
    def __init__(self, topic_name: str, subscribers: int = 0):
        self.topic_name, self.subscribers, self.published = topic_name, subscribers, []

    def get_subscription_count(self) -> int:
        return self.subscribers

    def publish(self, data) -> None:
        self.published.append(data)


class _Node:
    def __init__(self):
        self.publishers = []
        self.timers = []

    def create_timer(self, period_s, callback, clock=None):
        self.timers.append((period_s, callback, clock))

    def create_publisher(self, msg_type, name, qos):
        self.publishers.append(_Publisher('/' + name))
        return self.publishers[-1]


def _step_recorder():
    from ato_ros.publishing import StepRecorder
    node = _Node()
    return StepRecorder(node, lambda publisher, data: publisher.publish(data)), node


class _LocalRecorder:
    """A recorder in the loop's process as the step recorder sees it (LocalRecorder): writes
    each topic but ``/not_recorded`` at its stamp, ``/receipt`` at its own time (the last
    ``/clock`` stamp plus 1 ns), reads its time from ``/clock``, and wants to be told every
    ``every_ns`` of log time."""

    def __init__(self, every_ns: int):
        self.every_ns, self.written, self.told, self.asked = every_ns, [], [], []
        self.now_ns = 0

    def log_for(self, topic):
        from ato_ros.publishing import NOT_WRITTEN, TopicWrite
        self.asked.append(topic)
        if topic == '/not_recorded':
            return NOT_WRITTEN

        def write(data, log_time_ns):
            self.written.append((topic, log_time_ns, data))
        if topic == '/clock':
            def sets_time(stamp_ns):
                self.now_ns = stamp_ns
                return stamp_ns
            return TopicWrite(write, sets_time)
        if topic == '/receipt':
            return TopicWrite(write, lambda stamp_ns: self.now_ns + 1)
        return TopicWrite(write)

    def wrote(self, counts, first_ns, last_ns):
        self.told.append((dict(counts), first_ns, last_ns, len(self.written)))
        return last_ns + self.every_ns


def test_an_in_process_recorder_is_written_in_one_go_when_its_file_is_due():
    """The composed stack's recorder (StepRecorder.attach): no bundle, no publish; the messages
    kept as they are added (the time-setting part of a topic's write done at once) and written
    in one go, in order, when the recorder asked to be told, at a flush, a forget and a detach,
    by the function it gave for each topic (asked once per topic until forget); a message added
    with add_later made only then, from the arguments given at the add; the nodes count it as
    a recorder on the step records."""
    records, node = _step_recorder()
    assert not records.begin_step() and records.publisher.get_subscription_count() == 0
    every_ns = 1_000_000_000
    local = _LocalRecorder(every_ns)
    records.attach(local)
    assert records.publisher.get_subscription_count() == 1
    state, clock, other, receipt, later = (
        _Publisher('/train/state'), _Publisher('/clock'), _Publisher('/not_recorded'),
        _Publisher('/receipt'), _Publisher('/later'))
    made = []

    def encode(k, tag):
        made.append(k)
        return b'%s%d' % (tag, k)
    total = 14
    for k in range(total):
        stamp = k * 100_000_000
        assert records.begin_step()
        records.add(clock, stamp, b'c%d' % k)
        assert local.now_ns == stamp  # the recorder's time set as the message is added
        records.add(state, stamp, b's%d' % k)
        records.add(other, stamp, b'o%d' % k)
        records.add(receipt, stamp + 7, b'r%d' % k)
        records.add_later(later, stamp, encode, k, b'l')
        if k == 1:
            assert local.written[-1] == ('/later', 0, b'l0')  # the first step told at once
            assert made == [0]
        elif 1 < k < 11:
            assert len(local.written) == 4 and made == [0]  # kept, not yet made
        records.end_step(stamp)
    records.flush()
    assert local.asked == ['/clock', '/train/state', '/not_recorded', '/receipt', '/later']
    assert local.written == [(name, k * 100_000_000 + offset, b'%s%d' % (tag, k))
                             for k in range(total)
                             for name, offset, tag in (('/clock', 0, b'c'),
                                                       ('/train/state', 0, b's'),
                                                       ('/receipt', 1, b'r'),
                                                       ('/later', 0, b'l'))]
    assert made == list(range(total))
    # told at the first step (no due time yet), then once what was kept reached the log time
    # the recorder gave (1_000_000_001: the step after, the last message of a step being at
    # its stamp), then at the flush; each time after everything kept was written
    counts = {'/clock': 1, '/train/state': 1, '/receipt': 1, '/later': 1}
    assert local.told == [(counts, 0, 1, 4),
                          ({k: 11 for k in counts}, 100_000_000, 1_100_000_001, 48),
                          ({k: 2 for k in counts}, 1_200_000_000, 1_300_000_001, 56)]
    told = len(local.told)
    records.forget()  # what the recorder records changed: each topic asked for again
    assert len(local.told) == told  # nothing kept since the flush: nothing to tell
    assert records.begin_step()
    records.add(state, 1_400_000_000, b's14')
    assert local.asked[-1] == '/train/state' and len(local.asked) == 6
    assert len(local.written) == 56  # kept
    records.detach()  # the recorder stops: what was kept written and told, then not counted
    assert local.written[-1] == ('/train/state', 1_400_000_000, b's14')
    assert local.told[-1] == ({'/train/state': 1}, 1_400_000_000, 1_400_000_000, 57)
    assert records.publisher.get_subscription_count() == 0
    assert not records.begin_step()
    records.add(state, 1_500_000_000, b's15')
    records.add_later(later, 1_500_000_000, encode, 15, b'l')
    records.flush()
    assert len(local.written) == 57 and made == list(range(total))
    assert node.publishers[0].published == []  # nobody subscribed through the middleware


def test_a_message_added_later_is_made_at_once_for_a_recorder_in_another_process():
    """add_later beside a recorder in another process: the bytes made as the message is added
    (they go into the bundle), and the bundle as with add."""
    from ato_ros.step_records import read_bundle
    records, node = _step_recorder()
    records.recorders = lambda: 1  # a recorder in another process subscribes
    later = _Publisher('/later')
    assert records.begin_step()
    records.add_later(later, 1_000_000_000, lambda k: b'x%d' % k, 3)
    records.flush()
    (data,) = node.publishers[0].published
    names, entries = read_bundle(data)
    assert names == ['/later'] and [(e[1], e[-1]) for e in entries] == [(1_000_000_000, b'x3')]


def test_a_bundle_no_step_sends_is_sent_by_the_wall_timer():
    """A bundle begun at a step after which no step comes (a profile whose first bundle a
    recorder waits for, beside a plant held for that recorder's acknowledgement) is sent once it
    is a wall period old, by the node's steady-clock timer; a fresh one is not."""
    from rclpy.clock import ClockType

    from ato_ros.step_records import WALL_PERIOD_S, read_bundle
    records, node = _step_recorder()
    (period_s, send_stale, clock), = node.timers
    assert period_s == WALL_PERIOD_S and clock.clock_type == ClockType.STEADY_TIME
    records.recorders = lambda: 1  # a recorder in another process subscribes
    reference = _Publisher('/ato/reference')
    assert records.begin_step()
    records.add(reference, 1_700_000_000, b'r17')
    records.end_step(1_700_000_000)  # a period of stamps not reached: kept
    send_stale()
    assert node.publishers[0].published == []  # not yet a wall period old
    records.bundle.first_wall -= WALL_PERIOD_S
    send_stale()
    (data,) = node.publishers[0].published
    names, entries = read_bundle(data)
    assert names == ['/ato/reference'] and [e[1] for e in entries] == [1_700_000_000]
    send_stale()  # nothing left to send
    assert len(node.publishers[0].published) == 1
