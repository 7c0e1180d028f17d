"""The peers of ``guidebot bench hub --peer``: broadcasts with none of the hub's work.

``fastapi`` (the default): the ``ConnectionManager`` of FastAPI's "WebSockets" tutorial, as a
user would copy it: a list of sockets, ``send_text`` to each in turn. ``picows``: the least a
broadcast costs on the machine, a WebSocket server written in Cython that sends each robot frame
to every GUI from the callback that received it, so one frame costs a few microseconds of
Python. Robots send on ``/ws/robot``; every frame goes to every socket of ``/ws/gui``. Neither
has authentication, validation, routing or per-client queues, and one GUI that reads slowly
holds up the broadcast to all of them: that is what the hub adds.
"""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import FastAPI, WebSocket, WebSocketDisconnect

__all__ = ["ConnectionManager", "create_peer_app", "serve_picows_broadcast"]


class ConnectionManager:
    """As in FastAPI's documentation (tutorial, "Handling disconnections and multiple clients")."""

    def __init__(self) -> None:
        self.active_connections: list[WebSocket] = []

    async def connect(self, websocket: WebSocket) -> None:
        await websocket.accept()
        self.active_connections.append(websocket)

    def disconnect(self, websocket: WebSocket) -> None:
        self.active_connections.remove(websocket)

    async def broadcast(self, message: str) -> None:
        for connection in self.active_connections:
            await connection.send_text(message)


def create_peer_app() -> FastAPI:
    app = FastAPI()
    manager = ConnectionManager()

    @app.websocket("/ws/gui")
    async def gui(websocket: WebSocket) -> None:
        await manager.connect(websocket)
        try:
            while True:
                await websocket.receive_text()
        except WebSocketDisconnect:
            manager.disconnect(websocket)

    @app.websocket("/ws/robot")
    async def robot(websocket: WebSocket) -> None:
        await websocket.accept()
        try:
            while True:
                await manager.broadcast(await websocket.receive_text())
        except WebSocketDisconnect:
            pass

    return app


async def serve_picows_broadcast() -> tuple[asyncio.AbstractServer, int]:
    """The picows broadcast on 127.0.0.1 (a free port): (server, port)."""
    from picows import WSListener, WSMsgType, WSTransport, WSUpgradeRequest, ws_create_server

    guis: list[WSTransport] = []

    class Gui(WSListener):  # type: ignore[misc]
        def on_ws_connected(self, transport: WSTransport) -> None:
            guis.append(transport)

        def on_ws_disconnected(self, transport: WSTransport) -> None:
            if transport in guis:
                guis.remove(transport)

    class Robot(WSListener):  # type: ignore[misc]
        def on_ws_frame(self, transport: WSTransport, frame: Any) -> None:
            if frame.msg_type == WSMsgType.TEXT:
                data = frame.get_payload_as_bytes()
                for gui in guis:
                    gui.send(WSMsgType.TEXT, data)

    def route(request: WSUpgradeRequest) -> WSListener:
        return Gui() if bytes(request.path).endswith(b"/gui") else Robot()

    server = await ws_create_server(route, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]
