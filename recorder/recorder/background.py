"""A bag written on a thread of its own: the composed stack's recorder (``recorder.node`` in the
process of the loop) hands its messages on and goes back to the loop at once.

:class:`BackgroundWriter` has the calls of :class:`recorder.bag.BagWriter` that the recorder
makes (``add_topic``, ``write_many``, ``flush``, ``close``); each is queued and the writer thread
makes it on the bag in the same order. Writing is the Foxglove SDK's compiled MCAP writer, so the
thread holds Python's lock only for a call per message and for closing a chunk. A write error
(a full disk) is raised by the next call of the node's thread (and by ``close``).

Back-pressure: ``write_many`` waits while the messages handed on run more than ``lead_ns`` of
their log times (simulated time in lockstep) ahead of what the file holds, flushed: a writer
starved of CPU holds the loop instead of letting what it has not written grow, so a process
killed at any moment leaves a bag that lacks at most the lead, plus the messages the nodes had
not yet handed on (``ato_ros.publishing.StepRecorder``).
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Callable

from recorder.bag import BagError, BagInfo, BagWriter

#: how long a hand-off may wait for the writer before the recorder says so (and again every
#: such period), s of wall time
SLOW_WRITER_S = 5.0


class BackgroundWriter:
    def __init__(self, writer: BagWriter, lead_ns: int,
                 on_slow: Callable[[str], None] = lambda text: None):
        self.writer = writer
        self.path, self.folder = writer.path, writer.folder
        self.flush_period_s = writer.flush_period_s
        self.lead_ns = lead_ns
        self.on_slow = on_slow
        self.topics: dict[str, str] = {}  # topic -> type, as handed on (the bag's own: writer)
        self.closed = False
        self.handed_ns: int | None = None  # the newest log time handed on
        self.first_ns: int | None = None  # the first one: the file holds "up to" it at first
        self.flushed_ns: int | None = None  # the newest log time in the file, flushed
        self.error: BagError | None = None
        self.waited_s = 0.0  # how long hand-offs waited for the writer in all
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._progress = threading.Condition()
        self._thread = threading.Thread(target=self._run, name='bag writer', daemon=True)
        self._thread.start()

    # --- the node's thread ----------------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, offered_qos_profiles=(),
                  type_description_hash: str | None = None) -> None:
        self._check()
        if topic not in self.topics:
            self.topics[topic] = type_name
            self._queue.put((self.writer.add_topic, (topic, type_name, offered_qos_profiles,
                                                     type_description_hash)))

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self.write_many([(topic, log_time_ns, data)])

    def write_many(self, messages: list[tuple[str, int, bytes]],
                   newest_ns: int | None = None) -> None:
        """Queue ``messages`` (topic, log time ns, bytes); with ``newest_ns`` (the newest log
        time among them: the step records' stamps), wait while it is more than the lead ahead
        of the file."""
        self._check()
        if not messages:
            return
        self._queue.put((self._write, (messages, newest_ns)))
        if newest_ns is not None:
            if self.first_ns is None:
                self.first_ns = newest_ns
            if self.handed_ns is None or newest_ns > self.handed_ns:
                self.handed_ns = newest_ns
            self._hold(newest_ns, self.first_ns)

    def write_indexed(self, names: list[str], entries: list) -> None:
        """The entries of a bundle of step records (``BagWriter.write_indexed``) from another
        process: queued as ``write_many`` (no back-pressure: the plant of those waits for this
        recorder's acknowledgements)."""
        self.write_many([(names[index], log_time_ns, data)
                         for index, log_time_ns, _, data in entries])

    def _on_disk_ns(self, first_ns: int) -> int:
        return first_ns if self.flushed_ns is None else self.flushed_ns

    def _hold(self, newest_ns: int, first_ns: int) -> None:
        if newest_ns - self._on_disk_ns(first_ns) <= self.lead_ns:
            return
        started = time.monotonic()
        told = started
        with self._progress:
            while self.error is None and not self.closed and \
                    newest_ns - self._on_disk_ns(first_ns) > self.lead_ns:
                self._progress.wait(0.1)
                now = time.monotonic()
                if now - told >= SLOW_WRITER_S:
                    told = now
                    self.on_slow(f'the loop has waited {now - started:.1f} s of wall time for '
                                 f'the bag writer, whose file holds the step records up to '
                                 f'{self._on_disk_ns(first_ns) / 1e9:.3f} s (lead '
                                 f'{self.lead_ns / 1e9:g} s)')
        self.waited_s += time.monotonic() - started
        self._check()

    def flush(self) -> None:
        self._check()
        self._queue.put((self._flush, ()))

    def close(self) -> BagInfo:
        """Write everything queued, finish the file; BagError if a write failed."""
        if not self.closed:
            self.closed = True
            done = threading.Event()
            self._queue.put((self._finish, (done,)))
            done.wait()
            self._thread.join()
        if self.error is not None:
            raise self.error
        return self.info

    def _check(self) -> None:
        if self.error is not None:
            raise self.error

    # --- the writer's thread --------------------------------------------------------------
    def _run(self) -> None:
        while True:
            call, args = self._queue.get()
            if self.error is not None and call != self._finish:
                continue  # the recording stopped: the node's thread is told at its next call
            try:
                call(*args)
            except BagError as error:
                with self._progress:
                    self.error = error
                    self._progress.notify_all()
            if call == self._finish:
                return

    def _write(self, messages: list, newest_ns: int | None) -> None:
        before = self.writer.flushed_ns
        self.writer.write_many(messages)
        if self.writer.flushed_ns != before:
            self._flushed()

    def _flush(self) -> None:
        self.writer.flush()
        self._flushed()

    def _flushed(self) -> None:
        with self._progress:
            self.flushed_ns = self.writer.flushed_ns
            self._progress.notify_all()

    def _finish(self, done: threading.Event) -> None:
        try:
            self.info = self.writer.close()
        finally:
            done.set()
