"""The plant's side of the recorders' acknowledgements (ato_ros.publishing.RecorderLead), with
a stand-in for the node: which steps wait, and which acknowledgements count."""

from types import SimpleNamespace

from ato_ros.publishing import RecorderLead
from ato_ros.wire import encode_header

S = 1_000_000_000
RECORDER = '/recorder'


class FakeNode:
    """What RecorderLead asks of its node: a subscription to ``recorded``, the publishers of
    that topic (one recorder), a logger."""

    def __init__(self):
        self.logged: list[str] = []
        self.callback = None

    def create_subscription(self, msg_type, name, callback, qos, raw=False):
        self.callback = callback
        return SimpleNamespace(topic_name=name, get_publisher_count=lambda: 1)

    def get_publishers_info_by_topic(self, name):
        return [SimpleNamespace(node_namespace='/', node_name='recorder')]

    def get_logger(self):
        return SimpleNamespace(info=lambda text, **_: self.logged.append(text),
                               warning=lambda text, **_: self.logged.append(text))

    def acknowledge(self, stamp_ns: int) -> None:
        self.callback(encode_header(stamp_ns, RECORDER))


def lead(node: FakeNode) -> tuple[RecorderLead, list[int]]:
    released: list[int] = []
    return RecorderLead(node, 1.7, lambda: released.append(1), refresh_s=0.0), released


def test_a_step_waits_until_the_recorder_has_acknowledged_within_the_lead():
    node = FakeNode()
    recorder_lead, released = lead(node)
    assert not recorder_lead.holds(0)  # the recorder appears at 0
    assert not recorder_lead.holds(17 * S // 10)
    assert recorder_lead.holds(18 * S // 10)  # 1.8 s past what it vouches for
    node.acknowledge(S // 10)
    assert released and not recorder_lead.holds(18 * S // 10)


def test_an_earlier_runs_acknowledgement_holds_nothing_back_nor_lets_anything_go():
    """The acknowledgements are latched: a plant started again beside a running recorder first
    gets that recorder's last one, of the earlier run, stamped past every step of this run. It
    vouches for nothing of this run: ignored (said once), the lead counts from where the
    recorder appeared, until it acknowledges this run's records."""
    node = FakeNode()
    recorder_lead, released = lead(node)
    node.acknowledge(300 * S)  # latched, of the earlier run, before this run's first step
    assert not recorder_lead.holds(0)
    node.acknowledge(300 * S)
    assert recorder_lead.holds(18 * S // 10), 'an earlier run\'s acknowledgement let a step go'
    assert not released
    assert any('earlier run' in text for text in node.logged)
    node.acknowledge(S)  # this run's
    assert released and not recorder_lead.holds(18 * S // 10)


def test_the_last_step_waits_for_nothing_and_its_acknowledgement_counts():
    node = FakeNode()
    recorder_lead, _ = lead(node)
    assert not recorder_lead.holds(0)
    assert not recorder_lead.holds(30 * S, last=True)
    node.acknowledge(30 * S)
    assert not any('earlier run' in text for text in node.logged)


def test_a_recorder_the_graph_cannot_name_yet_is_not_taken_for_one_that_never_acknowledges():
    """A loaded machine can deliver a participant's node names well after its endpoints: the
    graph then names the recorder's publisher _NODE_NAME_UNKNOWN_. That publisher is not
    counted as a recorder of its own (it would never acknowledge under that name and hold the
    loop a lead after it appeared, as a stress run showed with the recorder stopped), nor does
    it make the plant forget the recorder that acknowledges under its real name; once named, the
    recorder is counted as usual."""
    node = FakeNode()
    unknown = SimpleNamespace(node_namespace='_NODE_NAMESPACE_UNKNOWN_',
                              node_name='_NODE_NAME_UNKNOWN_')
    graph = [unknown]
    node.get_publishers_info_by_topic = lambda name: list(graph)
    recorder_lead, released = lead(node)
    assert not recorder_lead.holds(0)
    assert not recorder_lead.holds(S // 10)
    node.acknowledge(S // 10)
    assert not recorder_lead.holds(18 * S // 10)  # 1.7 s past what /recorder vouches for
    assert recorder_lead.holds(19 * S // 10)
    recorder_lead.check()  # the timer while held: the graph names nobody yet
    assert recorder_lead.holds(19 * S // 10)
    assert f'for recorder {RECORDER}, whose file holds the step records up to 0.100 s' in \
        recorder_lead.waiting()
    node.acknowledge(S)
    assert released and not recorder_lead.holds(19 * S // 10)
    graph[:] = [SimpleNamespace(node_namespace='/', node_name='recorder')]  # named now
    assert not recorder_lead.holds(27 * S // 10)
    assert recorder_lead.holds(28 * S // 10)  # the same recorder, as it acknowledged
    assert RECORDER in recorder_lead.waiting()
