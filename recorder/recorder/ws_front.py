"""The live view's door: the WebSocket handshake of the Foxglove WebSocket protocol under either
of its two names, then the connection handed through to the Foxglove SDK's server.

The SDK's server (``foxglove.start_server``) speaks the protocol as ``foxglove.sdk.v1`` and
answers a client that asks for any other subprotocol with HTTP 400 and no reason a user can act
on. Foxglove states that ``foxglove.sdk.v1`` is the same protocol as ``foxglove.websocket.v1``
under a new name (clients of the older name: older Foxglove releases, Lichtblick, PlotJuggler's
plugin, scripts built on ``foxglove-websocket``). So the live view listens itself and, per
connection, reads the client's upgrade request:

- a client that asks for ``foxglove.sdk.v1`` is passed through unchanged;
- one that asks for ``foxglove.websocket.v1`` (only) has its request passed on asking for
  ``foxglove.sdk.v1`` and the server's answer passed back naming ``foxglove.websocket.v1``, the
  subprotocol it asked for (the handshake's key and accept do not involve the subprotocol);
- any other request gets HTTP 400 with a text saying what the server speaks.

After the handshake the bytes go both ways untouched. The SDK's server listens on the loopback
interface at a port of its own (:attr:`upstream_port`); the port users connect to is this one.
"""

from __future__ import annotations

import asyncio
import re
import threading

SDK_SUBPROTOCOL = 'foxglove.sdk.v1'
OLDER_SUBPROTOCOL = 'foxglove.websocket.v1'
SUBPROTOCOLS = (SDK_SUBPROTOCOL, OLDER_SUBPROTOCOL)
#: the largest HTTP request head a client may send before its upgrade is refused
MAX_HEAD = 64 * 1024
_PROTOCOL_HEADER = re.compile(rb'^sec-websocket-protocol:(.*)$', re.IGNORECASE | re.MULTILINE)
REFUSAL = ('This is the live view of the ATO emulator: a Foxglove WebSocket server. Connect '
           f'with a WebSocket client asking for the subprotocol {SDK_SUBPROTOCOL} or '
           f'{OLDER_SUBPROTOCOL} (Foxglove: Open connection, Foxglove WebSocket).\n')


def requested_subprotocols(head: bytes) -> list[str]:
    """The subprotocols an HTTP request head asks for (every Sec-WebSocket-Protocol header,
    comma-separated values), in order."""
    found = []
    for match in _PROTOCOL_HEADER.finditer(head.replace(b'\r\n', b'\n')):
        found += [p.strip() for p in match.group(1).decode('latin-1').split(',') if p.strip()]
    return found


def with_subprotocol(head: bytes, subprotocol: str) -> bytes:
    """``head`` with its Sec-WebSocket-Protocol headers replaced by one naming ``subprotocol``
    (the header kept where the first one was)."""
    lines = head.split(b'\r\n')
    out, done = [], False
    for line in lines:
        if _PROTOCOL_HEADER.match(line):
            if not done:
                out.append(b'Sec-WebSocket-Protocol: ' + subprotocol.encode())
                done = True
            continue
        out.append(line)
    return b'\r\n'.join(out)


def refusal(reason: str) -> bytes:
    body = (REFUSAL + reason + '\n').encode()
    return (b'HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\n'
            b'Content-Length: ' + str(len(body)).encode() + b'\r\nConnection: close\r\n\r\n'
            + body)


class Front:
    """Listens on ``host``:``port`` (0: any free port, then :attr:`port`) on a thread of its own
    and hands each WebSocket connection through to the SDK's server at ``upstream_port`` on
    the loopback interface. OSError if the port cannot be had."""

    def __init__(self, host: str, port: int, upstream_port: int):
        self.upstream_port = upstream_port
        self.loop = asyncio.new_event_loop()
        self.server = self.loop.run_until_complete(
            asyncio.start_server(self.handle, host, port, limit=MAX_HEAD))
        self.port = self.server.sockets[0].getsockname()[1]
        self.refused = 0
        self.thread = threading.Thread(target=self.loop.run_forever, name='live view front',
                                       daemon=True)
        self.thread.start()

    def stop(self) -> None:
        async def close() -> None:
            self.server.close()
            await self.server.wait_closed()
        asyncio.run_coroutine_threadsafe(close(), self.loop).result(timeout=5)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        upstream = None
        try:
            try:
                head = await reader.readuntil(b'\r\n\r\n')
            except (asyncio.IncompleteReadError, asyncio.LimitOverrunError):
                return
            asked = requested_subprotocols(head)
            if SDK_SUBPROTOCOL in asked:
                renamed = None
            elif OLDER_SUBPROTOCOL in asked:
                renamed, head = OLDER_SUBPROTOCOL, with_subprotocol(head, SDK_SUBPROTOCOL)
            else:
                self.refused += 1
                writer.write(refusal(f'This request asked for {", ".join(asked) or "none"}.'))
                await writer.drain()
                return
            up_reader, upstream = await asyncio.open_connection(
                '127.0.0.1', self.upstream_port, limit=MAX_HEAD)
            upstream.write(head)
            answer = await up_reader.readuntil(b'\r\n\r\n')
            if renamed is not None and answer.startswith(b'HTTP/1.1 101'):
                answer = with_subprotocol(answer, renamed)
            writer.write(answer)
            await asyncio.gather(self.pipe(reader, upstream), self.pipe(up_reader, writer))
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError):
            pass  # a client or the server went away: that connection ends
        finally:
            for stream in (writer, upstream):
                if stream is not None:
                    stream.close()

    @staticmethod
    async def pipe(source: asyncio.StreamReader, target: asyncio.StreamWriter) -> None:
        try:
            while data := await source.read(65536):
                target.write(data)
                await target.drain()
        finally:
            target.close()
