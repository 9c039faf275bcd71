"""The composed stack's bag writer on a thread of its own (recorder.background): everything
handed on is written in order, the hand-off waits while the writer is more than its lead
behind the file, and a write error reaches the node's thread."""

import threading
import time

import pytest
from test_bag import STATE_TYPE, descriptor_of, state_bytes

from recorder.background import BackgroundWriter
from recorder.bag import BagError, BagWriter, read_messages

LEAD_NS = 1_000_000_000


def writer_in(folder, **options) -> BagWriter:
    writer = BagWriter(folder, **options)
    writer.add_topic('/train/state', STATE_TYPE)
    return writer


def test_everything_handed_on_is_written_in_order(tmp_path):
    background = BackgroundWriter(writer_in(tmp_path / 'run'), LEAD_NS)
    for k in range(0, 100, 4):  # four steps a hand-off, as the step recorder does
        batch = [('/train/state', j * 100_000_000, state_bytes(j)) for j in range(k, k + 4)]
        background.write_many(batch, batch[-1][1])
    info = background.close()
    assert info.message_count == 100
    assert [m.data for m in read_messages(tmp_path / 'run')] == [state_bytes(k)
                                                                 for k in range(100)]


def test_the_hand_off_waits_while_the_file_is_more_than_the_lead_behind(tmp_path):
    writer = writer_in(tmp_path / 'run', flush_period_s=3600.0, flush_period_log_s=0.5)
    background = BackgroundWriter(writer, LEAD_NS)
    held = threading.Event()
    writing = threading.Event()
    real = writer.write_many

    def slow(messages):  # a writer starved of CPU: it waits to be let go
        writing.set()
        held.wait()
        real(messages)
    writer.write_many = slow
    background.write_many([('/train/state', 0, state_bytes(0))], 0)
    assert writing.wait(5)
    done = threading.Event()

    def hand_on():  # 1.5 s of stamps past what the file holds: over the lead
        background.write_many([('/train/state', 1_500_000_000, state_bytes(15))], 1_500_000_000)
        done.set()
    threading.Thread(target=hand_on, daemon=True).start()
    assert not done.wait(0.5)  # held
    held.set()
    assert done.wait(10)  # the writer caught up (flushed): let go
    assert background.waited_s > 0.3
    assert background.close().message_count == 2


def test_a_write_error_reaches_the_node_s_thread(tmp_path, monkeypatch):
    import os
    from collections import namedtuple

    from recorder import bag
    writer = writer_in(tmp_path / 'run', chunk_size=1 << 20)
    background = BackgroundWriter(writer, 10 ** 12)
    full = os.open('/dev/full', os.O_WRONLY)
    os.dup2(full, descriptor_of(writer.path))
    usage = namedtuple('usage', 'total used free')
    monkeypatch.setattr(bag.shutil, 'disk_usage', lambda path: usage(1 << 30, 1 << 30, 0))
    with pytest.raises(BagError, match='No space left on device'):
        for k in range(20000):
            background.write_many([('/train/state', k * 100_000_000, state_bytes(k % 50))])
            background.flush()
            time.sleep(0.0001)
    with pytest.raises(BagError):
        background.close()
