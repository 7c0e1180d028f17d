"""The peer of ``guidebot bench hub --peer``: FastAPI's documented WebSocket broadcast.

The ``ConnectionManager`` of FastAPI's "WebSockets" tutorial, as a user would copy it: a list
of sockets, ``send_text`` to each in turn. Robots send on ``/ws/robot``; every frame goes to
every socket of ``/ws/gui``. No authentication, validation, routing or per-client queue, and
one GUI that reads slowly holds up the loop over all of them: that is what the hub adds.
"""

from __future__ import annotations

from fastapi import FastAPI, WebSocket, WebSocketDisconnect

__all__ = ["ConnectionManager", "create_peer_app"]


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
