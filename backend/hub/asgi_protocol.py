"""uvicorn's sans-I/O WebSocket protocol, ending a failed connection the way websockets' own
server does, so that a client still sending learns why it was closed.

uvicorn fails a connection (a message over ``ws_max_size``: close code 1009; a protocol error:
1002) by writing the close frame and closing the socket at once. A socket closed with unread
data answers with a TCP reset, and a client still writing the rest of its message then has its
connection reset before it reads the close frame that says why (asyncio drops what the socket
holds when a write fails): it sees "no close frame received". ``LingeringWebSocketProtocol``
writes the close frame, then the end of its stream (a half-close), and reads on, dropping what
comes (websockets' protocol discards it once failed), until the client closes, or until
uvicorn's closing time-out (10 s) runs out. Test: tests/hub/test_listener.py.
"""

from __future__ import annotations

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol


class LingeringWebSocketProtocol(WebSocketsSansIOProtocol):
    """The /ws route's protocol (backend.app.uvicorn_config): uvicorn's, but a connection it
    fails reads on until the client closes instead of resetting it."""

    failed = False

    def handle_parser_exception(self) -> None:
        # uvicorn calls this for every read after the failure too: what comes then is dropped.
        if self.failed:
            return
        self.failed = True
        self.stop_keepalive()
        close = self.conn.close_sent
        assert close is not None
        self.queue.put_nowait(
            {"type": "websocket.disconnect", "code": close.code, "reason": close.reason}
        )
        self.close_sent = True
        for data in self.conn.data_to_send():  # the close frame, then b"": the end of the stream
            if data:
                self.transport.write(data)
            elif self.transport.can_write_eof():
                self.transport.write_eof()
        if self.read_paused:
            self.read_paused = False
            self.transport.resume_reading()
        if self.close_timer is None:
            self.close_timer = self.loop.call_later(self.close_timeout, self.transport.close)
