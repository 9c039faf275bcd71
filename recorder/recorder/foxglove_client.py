"""A minimal Foxglove WebSocket protocol client (what the Foxglove app does to watch a live
view), on a thread of its own: it connects, sends JSON operations (subscribe, unsubscribe), and
queues every frame it receives. ``make bench`` and the tests use it to watch ``recorder live``
as a Foxglove panel would; a script can use it to check a live view without the app.

Frames (Foxglove WebSocket protocol): text frames are JSON (``serverInfo``, ``advertise``...);
a binary frame of opcode 1 is a message: uint32 subscription id, uint64 log time (ns, little
endian), then the message's bytes (CDR for the suite's channels).
"""

from __future__ import annotations

import asyncio
import json
import queue
import struct
import threading
import time
from typing import Callable

from tornado.websocket import websocket_connect

SUBPROTOCOL = 'foxglove.sdk.v1'
MESSAGE_DATA = 0x01


class FoxgloveClient:
    """Connects to ``url`` (``ws://host:port``) asking for ``subprotocol``; frames land in
    ``received``, and the channels the server advertises (and has not withdrawn) in
    ``channels``, by topic; ``connection.selected_subprotocol`` is the server's answer."""

    def __init__(self, url: str, timeout_s: float = 10.0, subprotocol: str = SUBPROTOCOL):
        self.subprotocol = subprotocol
        self.received: queue.Queue = queue.Queue()
        self.channels: dict[str, dict] = {}
        self._lock = threading.Lock()
        self.loop = asyncio.new_event_loop()
        self.connected = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, args=(url,), daemon=True)
        self.thread.start()
        if not self.connected.wait(timeout_s) or self.error is not None:
            raise ConnectionError(f'no Foxglove WebSocket connection to {url}: '
                                  f'{self.error or "timed out"}')

    def _run(self, url: str) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(self._connect(url))
        except Exception as error:  # noqa: BLE001 -- reported by __init__
            self.error = error
            self.connected.set()
            return
        self.loop.run_forever()

    async def _connect(self, url: str) -> None:
        self.connection = await websocket_connect(url, subprotocols=[self.subprotocol])
        self.connected.set()
        self.loop.create_task(self._read())

    async def _read(self) -> None:
        while True:
            message = await self.connection.read_message()
            if message is None:
                return
            if isinstance(message, str):
                self._note(json.loads(message))
            self.received.put(message)

    def _note(self, body: dict) -> None:
        with self._lock:
            if body.get('op') == 'advertise':
                self.channels.update({c['topic']: c for c in body['channels']})
            elif body.get('op') == 'unadvertise':
                gone = set(body['channelIds'])
                self.channels = {t: c for t, c in self.channels.items() if c['id'] not in gone}

    def channel(self, topic: str, timeout_s: float, spin: Callable[[], None] = lambda: None
                ) -> dict:
        """The channel the server advertises for ``topic`` (id, encoding, schema...), waiting
        for it up to ``timeout_s`` while calling ``spin``; TimeoutError naming the topic."""
        deadline = time.monotonic() + timeout_s
        while True:
            with self._lock:
                found = self.channels.get(topic)
            if found is not None:
                return found
            if time.monotonic() > deadline:
                raise TimeoutError(f'the live view did not advertise {topic} in {timeout_s} s')
            spin()
            time.sleep(0.01)

    def send(self, payload: dict) -> None:
        self.loop.call_soon_threadsafe(self.connection.write_message, json.dumps(payload))

    def subscribe(self, subscription_id: int, channel_id: int) -> None:
        self.send({'op': 'subscribe',
                   'subscriptions': [{'id': subscription_id, 'channelId': channel_id}]})

    def unsubscribe(self, subscription_id: int) -> None:
        self.send({'op': 'unsubscribe', 'subscriptionIds': [subscription_id]})

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.connection.close)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)

    def next(self, accept: Callable[[object], object], timeout_s: float,
             spin: Callable[[], None] = lambda: None):
        """The first frame for which ``accept`` returns something (that something), calling
        ``spin`` while waiting; TimeoutError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            spin()
            try:
                message = self.received.get(timeout=0.05)
            except queue.Empty:
                continue
            found = accept(message)
            if found is not None:
                return found
        raise TimeoutError(f'nothing awaited arrived from the live view in {timeout_s} s')


def message_data(subscription_id: int) -> Callable[[object], tuple[int, bytes] | None]:
    """Accepts a message of a subscription: (log time in ns, the message's bytes)."""
    def accept(message):
        if isinstance(message, bytes) and message[0] == MESSAGE_DATA:
            sid, log_time = struct.unpack_from('<IQ', message, 1)
            if sid == subscription_id:
                return log_time, message[13:]
        return None
    return accept
