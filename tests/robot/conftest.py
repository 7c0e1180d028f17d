"""Shared pieces of the robot agent tests: the demo site and a building stand-in on a Bus."""

from __future__ import annotations

import asyncio
import functools
from pathlib import Path
from types import SimpleNamespace

import pytest

from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file
from guidebot.testing import Recorder

ROOT = Path(__file__).resolve().parents[2]
DEMO_SITE = ROOT / "sites" / "demo_museum.yaml"


@pytest.fixture(scope="session")
def demo_site() -> Site:
    return load_site_file(DEMO_SITE)


class BuildingStandIn:
    """Answers open_door and call_elevator on a Bus after a robot-time delay (unit tests only;
    the end-to-end tests use the real BuildingInterface over Modbus with building_sim)."""

    def __init__(self, bus: Bus, *, delay_s: float = 0.05) -> None:
        self.ep = bus.endpoint("building")
        self.delay_s = delay_s
        self.opened: list[str] = []
        self.calls: list[tuple[str, str]] = []
        self._tasks: set[asyncio.Task[None]] = set()
        self.ep.subscribe("open_door", self._on_open)
        self.ep.subscribe("call_elevator", self._on_call)

    def _later(self, type_: str, payload: dict[str, object]) -> None:
        async def send() -> None:
            await asyncio.sleep(self.delay_s)
            self.ep.publish(type_, payload)

        task = asyncio.get_running_loop().create_task(send())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _on_open(self, message: Message) -> None:
        door = str(message.payload["door"])
        self.opened.append(door)
        self._later("door_opened", {"door": door})

    def _on_call(self, message: Message) -> None:
        elevator, floor = str(message.payload["elevator"]), str(message.payload["floor"])
        self.calls.append((elevator, floor))
        self._later(
            "elevator_in_position", {"elevator": elevator, "floor": floor, "door_open": True}
        )


@pytest.fixture
def helpers() -> SimpleNamespace:
    """The helper classes, as a fixture: test modules here do not import each other."""
    return SimpleNamespace(
        Recorder=functools.partial(Recorder, tap=True),
        BuildingStandIn=BuildingStandIn,
        LinkCutter=LinkCutter,
    )


class LinkCutter:
    """A TCP relay on 127.0.0.1 between the robot and the server: ``cut()`` drops every
    connection and refuses new ones (the robot's Wi-Fi is gone), ``restore()`` listens again
    on the same port. A real network fault, not a mock of the client."""

    def __init__(self, target_port: int) -> None:
        self.target_port = target_port
        self.port = 0
        self.cuts = 0
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._tasks: set[asyncio.Task[None]] = set()

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._relay, "127.0.0.1", self.port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def _relay(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.target_port)
        except OSError:
            writer.close()
            return
        self._writers |= {writer, up_writer}

        async def pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            try:
                while data := await src.read(65536):
                    dst.write(data)
                    await dst.drain()
            except (ConnectionError, OSError):
                pass
            finally:
                dst.close()

        tasks = [
            asyncio.create_task(pump(reader, up_writer)),
            asyncio.create_task(pump(up_reader, writer)),
        ]
        self._tasks.update(tasks)
        await asyncio.gather(*tasks, return_exceptions=True)
        self._tasks.difference_update(tasks)
        self._writers -= {writer, up_writer}

    async def cut(self) -> None:
        self.cuts += 1
        for writer in list(self._writers):
            writer.transport.abort()
        self._writers.clear()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None

    async def restore(self) -> None:
        await self.start()

    async def stop(self) -> None:
        await self.cut()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
