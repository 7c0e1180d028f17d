"""What the hub's own listener (hub_ws_port) adds to the protocol, and where both listeners must
agree on WebSocket details the hub tests do not reach: fragments, size limits, closing."""

from __future__ import annotations

import asyncio
import contextlib
import socket

import orjson
import pytest
import websockets
from picows import WSFrame, WSListener, WSMsgType, WSTransport, ws_connect
from websockets.client import ClientProtocol
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.frames import Frame, Opcode
from websockets.uri import parse_uri

from backend.testing import RunningServer, running_server

from .conftest import TOKENS, hub_settings
from .test_security import authenticated, close_of, receive

WAIT = 10.0


async def forgotten(server: RunningServer, name: str) -> None:
    """The hub lets go of a client a moment after its socket ends."""
    for _ in range(200):
        if name not in server.app.state.hub.clients:
            return
        await asyncio.sleep(0.01)
    raise AssertionError(f"{name} still attached")


async def test_a_message_sent_in_several_frames_is_read_as_one(server: RunningServer) -> None:
    async for ws in authenticated(server, "R1"):
        await ws.send(['{"type": "ping",', ' "id": "in-parts"', "}"])
        pong = await receive(ws)
        assert pong["type"] == "pong" and pong["correlation_id"] == "in-parts"


async def test_a_message_over_16_mib_closes_the_connection_with_1009(
    server: RunningServer,
) -> None:
    async for ws in authenticated(server, "R1"):
        part = " " * (4 * 1024 * 1024)
        with contextlib.suppress(ConnectionClosed):  # it may close while we still send
            await ws.send(["[", *[part] * 4, "]"])  # 16 MiB and 2 bytes
        code, _ = await close_of(ws)
        assert code == 1009
    assert "R1" not in server.app.state.hub.clients


async def test_a_client_still_sending_when_refused_reads_the_1009_and_is_never_reset(
    server: RunningServer,
) -> None:
    """The server reads on (and drops) what follows a refused message until the client closes:
    a socket closed with unread data answers with a TCP reset, and a client still writing then
    loses the close frame that says why (seen as "no close frame received" on a loaded run)."""
    loop = asyncio.get_running_loop()
    client = ClientProtocol(parse_uri(server.hub_url), max_size=None)
    request = client.connect()
    request.headers["Authorization"] = f"Bearer {TOKENS['R1'].token}"
    client.send_request(request)
    with socket.create_connection((server.host, server.hub_port)) as sock:
        sock.setblocking(False)

        async def send_pending() -> None:
            await loop.sock_sendall(sock, b"".join(client.data_to_send()))

        async def received() -> list[Frame]:
            """What the next read brings; a reset raises ConnectionResetError here."""
            data = await asyncio.wait_for(loop.sock_recv(sock, 1 << 16), WAIT)
            if data:
                client.receive_data(data)
            else:
                client.receive_eof()
            return [e for e in client.events_received() if isinstance(e, Frame)]

        await send_pending()
        while not any(frame.opcode is Opcode.TEXT for frame in await received()):
            pass  # the handshake's answer, then the welcome
        part = b" " * (4 * 1024 * 1024)
        client.send_text(b"[", fin=False)
        for _ in range(4):
            client.send_continuation(part, fin=False)
        client.send_continuation(b"]", fin=True)
        await send_pending()  # 16 MiB and 2 bytes
        await forgotten(server, "R1")  # refused: the hub let go of R1
        client.send_text(b'{"type": "ping", "id": "too-late"}')
        await send_pending()  # still sending after the refusal
        while not client.reader.eof:  # the close frame, then the end of the stream
            await received()
        assert client.close_rcvd is not None
        assert client.close_rcvd.code == 1009


async def test_a_client_that_closes_is_forgotten(server: RunningServer) -> None:
    hub = server.app.state.hub
    async for ws in authenticated(server, "R1"):
        assert "R1" in hub.clients
        await ws.close()
        assert ws.close_code == 1000  # the listener answered the close handshake
    await forgotten(server, "R1")


async def test_the_listener_serves_the_hub_at_ws_only() -> None:
    async with running_server(hub_settings("picows")) as server:
        with pytest.raises(InvalidStatus) as refused:
            await websockets.connect(f"ws://127.0.0.1:{server.hub_port}/api/ws", proxy=None)
        assert refused.value.response.status_code == 404
        assert server.hub_port != server.port  # /ws on the HTTP port is there too
        async with websockets.connect(server.ws_url, proxy=None) as ws:
            code, _ = await close_of(ws)
            assert code == 4001


async def test_shutdown_tells_the_listener_clients_why() -> None:
    async with running_server(hub_settings("picows")) as server:
        headers = {"Authorization": f"Bearer {TOKENS['gui'].token}"}
        ws = await websockets.connect(server.hub_url, additional_headers=headers, proxy=None)
        assert orjson.loads(await asyncio.wait_for(ws.recv(), WAIT))["type"] == "welcome"
    code, reason = await close_of(ws)
    assert (code, reason) == (1001, "server shutting down")


async def test_the_listener_port_is_refused_when_taken() -> None:
    async with running_server(hub_settings("picows")) as first:
        with pytest.raises(RuntimeError, match="stopped before it started"):
            async with running_server(hub_settings(hub_ws_port=first.hub_port)):
                pass


async def test_fragments_out_of_order_close_the_connection_with_1002() -> None:
    closes: list[tuple[int, bytes]] = []

    class Client(WSListener):
        def on_ws_frame(self, transport: WSTransport, frame: WSFrame) -> None:
            if frame.msg_type is WSMsgType.CLOSE:
                closes.append((int(frame.get_close_code()), frame.get_close_message() or b""))

    async with running_server(hub_settings("picows")) as server:
        headers = {"Authorization": f"Bearer {TOKENS['R1'].token}"}
        transport, _ = await ws_connect(Client, server.hub_url, extra_headers=headers)
        transport.send(WSMsgType.CONTINUATION, b'"a part of nothing"')  # no message to continue
        await asyncio.wait_for(transport.wait_disconnected(), WAIT)
        assert closes == [(1002, b"fragments out of order")]
        await forgotten(server, "R1")
