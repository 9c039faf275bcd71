"""The live view's door (recorder.ws_front): which subprotocols a handshake asks for, the
handshake passed on under the SDK's name, and the refusal's text."""

from recorder.ws_front import (
    OLDER_SUBPROTOCOL,
    SDK_SUBPROTOCOL,
    refusal,
    requested_subprotocols,
    with_subprotocol,
)

REQUEST = (b'GET / HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\n'
           b'Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n'
           b'sec-websocket-protocol: x.v1, foxglove.websocket.v1\r\n'
           b'Sec-WebSocket-Protocol: other\r\n\r\n')


def test_every_subprotocol_asked_for_is_read_whatever_the_header_s_case():
    assert requested_subprotocols(REQUEST) == ['x.v1', OLDER_SUBPROTOCOL, 'other']
    assert requested_subprotocols(b'GET / HTTP/1.1\r\n\r\n') == []


def test_the_handshake_is_passed_on_naming_one_subprotocol():
    renamed = with_subprotocol(REQUEST, SDK_SUBPROTOCOL)
    assert requested_subprotocols(renamed) == [SDK_SUBPROTOCOL]
    assert renamed.startswith(b'GET / HTTP/1.1\r\nHost: 127.0.0.1:8765\r\n')
    assert renamed.endswith(b'\r\n\r\n') and b'Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==' \
        in renamed


def test_a_refusal_says_what_to_ask_for():
    answer = refusal('This request asked for none.')
    head, _, body = answer.partition(b'\r\n\r\n')
    assert head.startswith(b'HTTP/1.1 400 Bad Request')
    assert int(head.split(b'Content-Length: ')[1].split(b'\r\n')[0]) == len(body)
    assert SDK_SUBPROTOCOL.encode() in body and OLDER_SUBPROTOCOL.encode() in body
