"""Robots in a process of their own that follow the live site, for `bench traffic`'s reload
windows: each connects to the hub over WebSocket, and answers every ``site_changed`` (the whole
site, decoded) with ``site_loaded`` and its version, as a robot agent does once it has read it.
So a publish the bench measures is the real one: the hub writes the site to every robot.

They stand for robots on machines of their own, so the process runs at a lower priority
(``nice`` 10, as the server's worker processes) and takes only the CPU the server leaves.

    python -m bench.site_followers < {"url": "ws://...", "robots": [[name, token], ...]}

prints ``ready`` once every robot is welcomed and runs until its standard input closes; a
robot the hub refuses ends it at once (exit status 1, the reason on standard error).
"""

from __future__ import annotations

import asyncio
import os
import sys
from collections.abc import Callable

import orjson

from guidebot.client import HubClient
from guidebot.messages import Message

__all__ = ["follow"]

NICE = 10


async def follow(url: str, robots: list[tuple[str, str]], until: asyncio.Event) -> None:
    """Connect every (name, token) robot, answer site_changed until ``until`` is set."""
    clients = [HubClient(url, token, name=name) for name, token in robots]

    def answer(client: HubClient) -> Callable[[Message], None]:
        def on_changed(message: Message) -> None:
            client.publish("site_loaded", {"version": int(message.payload["version"])})

        return on_changed

    for client in clients:
        client.subscribe("site_changed", answer(client))
        await client.start()
    try:
        for client in clients:
            await asyncio.wait_for(client.connected.wait(), 60)
        print("ready", flush=True)
        await until.wait()
    finally:
        for client in clients:
            await client.close()


async def _main() -> None:
    config = orjson.loads(sys.stdin.readline())
    robots = [(str(name), str(token)) for name, token in config["robots"]]
    done = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_reader(sys.stdin.fileno(), lambda: done.set() if not sys.stdin.read(1) else None)
    await follow(config["url"], robots, done)


if __name__ == "__main__":
    if hasattr(os, "nice"):
        os.nice(NICE)
    asyncio.run(_main())
