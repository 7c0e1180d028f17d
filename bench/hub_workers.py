"""The processes of ``guidebot bench hub`` (bench/hub.py runs them as ``python -m
bench.hub_workers``): the server, a share of the robots, the GUIs; and the ``Probe`` each one
reports its event-loop lag and garbage collections with.

Each worker prints READY (or the server its PORT), reads the start time and the duration on
stdin, runs, and prints one JSON line of results.
"""

from __future__ import annotations

import argparse
import array
import asyncio
import contextlib
import gc
import json
import os
import sys
import time
from collections.abc import Sequence
from typing import Any

import orjson

from guidebot.benchutil import percentiles
from guidebot.messages import new_message_id
from guidebot.wire import encode

PEER_SERVERS = ("fastapi", "picows")
"""The broadcasts ``--peer`` can run (bench/hub_peer.py)."""

HUB_LISTENERS = ("picows", "asgi")
"""Where the hub's clients connect: its own listener (``hub_ws_port``), or /ws through uvicorn."""

__all__ = ["GUI_TOKEN", "SLOW_GUI", "WARMUP_S", "Probe", "robot_name", "robot_token"]

GUI_TOKEN = "bench-gui-token"
SLOW_GUI = "slowgui"
WARMUP_S = 1.0


def robot_name(i: int) -> str:
    return f"R{i + 1}"


def robot_token(i: int) -> str:
    return f"bench-robot-{i + 1}-token"


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class Probe:
    """Health of one bench process: event-loop lag and garbage-collector pauses.

    Lag: a task asks to wake every ``tick`` seconds and records how late it woke. A lagging robot
    or GUI process adds its lag to the measured latency, so each process reports its own. GC:
    collections per generation with their CPU time and longest wall-clock pause, the objects the
    collector still tracks at the end and how long one full collection of them takes (timed
    after the measured window).
    """

    def __init__(self, tick: float = 0.005) -> None:
        self.tick = tick
        self.lags: list[float] = []
        self.gc_count = [0, 0, 0]
        self.gc_cpu = [0.0, 0.0, 0.0]
        self.gc_max = 0.0
        self._gc_start = (0.0, 0.0)
        self._task: asyncio.Task[None] | None = None

    def _on_gc(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._gc_start = (time.perf_counter(), time.thread_time())
            return
        wall, cpu = self._gc_start
        generation = info["generation"]
        self.gc_count[generation] += 1
        self.gc_cpu[generation] += time.thread_time() - cpu
        self.gc_max = max(self.gc_max, time.perf_counter() - wall)

    def start(self, freeze: bool = False) -> None:
        """Start sampling; ``freeze``: move everything alive now out of the collector's way.

        A robot process of the bench holds hundreds of robots' connections in one heap (a real
        robot holds one): a full collection there takes 100+ ms and would count as hub latency.
        """
        if freeze:
            gc.collect()
            gc.freeze()
        gc.callbacks.append(self._on_gc)
        self._task = asyncio.create_task(self._run())

    async def _run(self) -> None:
        while True:
            due = time.perf_counter() + self.tick
            await asyncio.sleep(self.tick)
            self.lags.append(time.perf_counter() - due)

    def reset(self) -> None:
        self.lags.clear()
        self.gc_count = [0, 0, 0]
        self.gc_cpu = [0.0, 0.0, 0.0]
        self.gc_max = 0.0

    def report(self) -> dict[str, Any]:
        if self._task is not None:
            self._task.cancel()
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(self._on_gc)
        return {
            "lag_ms": {
                **percentiles([x * 1000 for x in self.lags], 1),
                "max": round(1000 * max(self.lags, default=0.0), 1),
            },
            "gc": {
                "collections": self.gc_count,
                "cpu_ms": [round(1000 * c, 1) for c in self.gc_cpu],
                "max_pause_ms": round(1000 * self.gc_max, 1),
            },
        }

    @staticmethod
    def full_collection(report: dict[str, Any]) -> dict[str, Any]:
        """Add the tracked objects and the time of one full collection (run it after the
        measured window: it stalls the process)."""
        t0 = time.perf_counter()
        gc.collect()
        report["gc"]["full_collection_ms"] = round(1000 * (time.perf_counter() - t0), 1)
        report["gc"]["tracked_objects"] = len(gc.get_objects())
        return report


# -- worker processes ----------------------------------------------------------------------------
async def _serve(robots: int, full_app: bool, peer: str | None, listener: str) -> None:
    """Server process (the hub with its clients on ``listener``, or the ``peer`` broadcast
    named): print the bound ports, then serve until killed."""
    import backend.app
    from backend.auth import Role
    from backend.settings import Settings, StaticToken
    from backend.testing import running_server

    from .hub_peer import create_peer_app, serve_picows_broadcast

    if peer == "picows":  # no app: the listener serves until the process is killed
        broadcast, port = await serve_picows_broadcast()
        async with broadcast:
            await _report_health(port)
        return
    if not full_app:
        backend.app.COMPONENTS = []
    tokens = [StaticToken(token=GUI_TOKEN, name="gui", role=Role.GUI)]
    tokens += [
        StaticToken(token=robot_token(i), name=robot_name(i), role=Role.ROBOT)
        for i in range(robots)
    ]
    settings = Settings(
        tokens=tokens,
        db_url=f"sqlite+aiosqlite:///{os.getcwd()}/.bench-hub-{os.getpid()}.db",
        hub_ws_port=0 if listener == "picows" and not peer else None,
    )
    app = create_peer_app() if peer else None
    async with running_server(settings, app=app) as server:
        if os.environ.get("BENCH_NO_GC_FREEZE") and not peer:  # the hub without its GC policy
            server.app.state.hub.memory.enabled = False
        await _report_health(server.port, server.hub_port)


async def _report_health(port: int, hub_port: int | None = None) -> None:
    """Print the HTTP port and the hub clients' port, follow the run's start and length from
    stdin, print the loop's health over the measured window once the GUIs are done, then wait
    to be killed."""
    print(f"PORT {port} {hub_port or port}", flush=True)
    probe = Probe()
    probe.start()
    start_at = await _read_start_time()
    seconds = await _read_start_time()
    await asyncio.sleep(max(0.0, start_at + WARMUP_S - time.time()))
    probe.reset()
    await asyncio.sleep(max(0.0, start_at + seconds - time.time()))
    health = probe.report()
    await _read_start_time()  # the GUIs are done
    print(json.dumps(Probe.full_collection(health)), flush=True)
    await asyncio.Event().wait()


async def _read_start_time() -> float:
    line = await asyncio.get_running_loop().run_in_executor(None, sys.stdin.readline)
    return float(line)


def _state_frame(name: str, seq: int) -> bytes:
    """A robot_state exactly as HubClient puts it on the wire (``encode(Message(...))``: the
    same fields in the same order), built without the model: a bench process sends thousands
    a second for hundreds of robots, and its CPU is taken from the server it measures."""
    return orjson.dumps(
        {
            "type": "robot_state",
            "id": new_message_id(),
            "timestamp": time.time(),
            "source": name,
            "destination": None,
            "correlation_id": None,
            "version": 1,
            "payload": {
                "robot": name,
                "x": 1.0,
                "y": 2.0,
                "theta": 0.5,
                "battery": 0.8,
                "seq": seq,
            },
        }
    )


async def _publish_states(
    links: list[Any], first: int, start_at: float, end_at: float, rate: float
) -> int:
    """Each robot sends ``rate`` states a second, the robots' phases spread evenly over the
    period, from ``start_at`` to ``end_at``; returns how many were sent.

    One timeline for all the process's robots (the n-th send is due at ``start_at + n *
    period / count``), woken about once a millisecond to send what is due, rather than a
    sleeping task per robot: a timer and a task switch per message cost the bench process more
    CPU than the send itself. Each state is stamped as it is sent."""
    from picows import WSMsgType

    count = len(links)
    names = [robot_name(first + k) for k in range(count)]
    step = 1.0 / rate / count
    seqs = [0] * count
    n = 0
    while True:
        due = start_at + n * step
        if due >= end_at:
            return n
        ahead = due - time.time()
        if ahead > 0.001:
            await asyncio.sleep(ahead - 0.0005)
            continue
        k = n % count
        seqs[k] += 1
        links[k].send(WSMsgType.TEXT, _state_frame(names[k], seqs[k]))
        n += 1


def _listener(on_text: Any) -> Any:
    """A picows listener that hands every text frame's payload (bytes) to ``on_text``."""
    from picows import WSFrame, WSListener, WSMsgType, WSTransport

    class Listener(WSListener):  # type: ignore[misc]
        def on_ws_frame(self, transport: WSTransport, frame: WSFrame) -> None:
            if frame.msg_type == WSMsgType.TEXT:
                on_text(frame.get_payload_as_bytes())
            elif frame.msg_type == WSMsgType.CLOSE:
                transport.disconnect()

    return Listener


async def _close(links: list[Any]) -> None:
    """Close picows links with the closing handshake: what was sent before is delivered. The
    code must be given: picows's default (1005, "no status") may not be sent in a close frame,
    and the server drops such a connection as a protocol error, with the frames before it."""
    from picows import WSCloseCode

    for link in links:
        link.send_close(WSCloseCode.OK)
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(10):
            await asyncio.gather(*(link.wait_disconnected() for link in links))
    for link in links:
        link.disconnect()


async def _robots(url: str, first: int, count: int, rate: float, peer: bool) -> None:
    """Robot process: connect ``count`` robots, wait for the start time, publish, report.

    The same client against both servers: one connection per robot, each robot_state sent as
    HubClient sends it (one text frame, the JSON envelope). The client is picows, a WebSocket
    client written in Cython: a real robot spends its own computer's CPU on its one link, but
    here hundreds of links share the machine with the server being measured.
    """
    from picows import ws_connect

    errors = [0]

    def count_errors(payload: bytes) -> None:
        if b'"error"' in payload:
            errors[0] += 1

    async def open_one(i: int) -> Any:
        headers = None if peer else {"Authorization": f"Bearer {robot_token(i)}"}
        transport, _ = await ws_connect(
            _listener(count_errors), url, extra_headers=headers, websocket_handshake_timeout=60
        )
        return transport

    links: list[Any] = []
    for start in range(first, first + count, 50):  # in waves: the accept queue is finite
        end = min(first + count, start + 50)
        links += await asyncio.gather(*(open_one(i) for i in range(start, end)))
    probe = Probe()
    probe.start(freeze=True)
    print("READY", flush=True)
    start_at = await _read_start_time()
    seconds = await _read_start_time()
    end_at = start_at + seconds
    probe.reset()
    cpu0, t0 = time.process_time(), time.monotonic()
    published = await _publish_states(links, first, start_at, end_at, rate)
    cpu_percent = 100 * (time.process_time() - cpu0) / (time.monotonic() - t0)
    health = probe.report()
    Probe.full_collection(health)
    await _close(links)
    result = {"published": published, "errors": errors[0], "cpu": cpu_percent, **health}
    print(json.dumps(result), flush=True)


class _Gui:
    """One GUI connection: frames and robot_state receipts, latency, sequence gaps."""

    def __init__(self, window: list[float], latencies: array.array[float], slow_s: float) -> None:
        self.window = window
        self.latencies = latencies
        self.slow_s = slow_s
        self.frames = 0
        self.received = 0
        self.gaps = 0
        self.last_frame = time.monotonic()
        self.seqs: dict[str, int] = {}
        self.slow: dict[int, float] = {}  # second of the window -> worst latency over 100 ms

    def take(self, frame: bytes | str, now: float) -> None:
        """Account for one frame received at ``now``."""
        window, latencies, seqs = self.window, self.latencies, self.seqs
        self.last_frame = time.monotonic()
        self.frames += 1
        data = orjson.loads(frame)
        for message in data if isinstance(data, list) else (data,):
            if message.get("type") != "robot_state":
                continue
            self.received += 1
            payload = message["payload"]
            robot, seq = payload["robot"], payload["seq"]
            previous = seqs.get(robot, 0)
            if seq > previous + 1:
                self.gaps += seq - previous - 1
            seqs[robot] = seq
            stamp = message["timestamp"]
            if window[0] <= stamp <= window[1]:
                latency = now - stamp
                latencies.append(latency)
                if latency > 0.1:
                    second = int(stamp - window[0])
                    self.slow[second] = max(self.slow.get(second, 0.0), latency)

    def on_text(self, frame: bytes) -> None:
        """A picows GUI's frame, handled as it is read."""
        self.take(frame, time.time())

    async def read_slowly(self, ws: Any) -> None:
        """The deliberately slow GUI (a ``websockets`` connection): read one frame, then pause
        ``slow_s`` before asking for the next, so the server's sends back up behind it."""
        with contextlib.suppress(Exception):
            async for frame in ws:
                now = time.time()
                self.take(frame, now)
                if now < self.window[1]:
                    await asyncio.sleep(self.slow_s)


def _subscription() -> tuple[list[bytes], bytes]:
    """The frames a GUI sends to follow robot_state (subscribe, then a ping), and what the
    pong's frame contains (the ping's id): once it comes, the subscription is applied."""
    from guidebot.messages import Message

    ping = Message(type="ping")
    subscribe = Message(type="subscribe", payload={"patterns": ["robot_state"]})
    return [encode(subscribe), encode(ping)], ping.id.encode()


async def _open_fast_gui(url: str, peer: bool, gui: _Gui) -> Any:
    """Connect a GUI over picows (see ``_robots``: the bench's clients must cost the machine
    little); on the hub, subscribe to robot_state and wait until it is applied."""
    from picows import WSMsgType, ws_connect

    if peer:
        transport, _ = await ws_connect(_listener(gui.on_text), f"{url}/gui")
        return transport
    frames, pong = _subscription()
    applied = asyncio.get_running_loop().create_future()

    def until_pong(frame: bytes) -> None:
        if applied.done():
            gui.on_text(frame)
        elif pong in frame:
            applied.set_result(None)

    transport, _ = await ws_connect(
        _listener(until_pong), url, extra_headers={"Authorization": f"Bearer {GUI_TOKEN}"}
    )
    for frame in frames:
        transport.send(WSMsgType.TEXT, frame)
    async with asyncio.timeout(30):
        await applied
    return transport


async def _open_gui(url: str, peer: bool, token: str, name: str | None = None) -> Any:
    """Connect a GUI; on the hub, subscribe to robot_state and wait until it is applied."""
    from websockets.asyncio.client import connect

    if peer:
        return await connect(f"{url}/gui", ping_interval=None)
    query = f"?name={name}" if name else ""
    ws = await connect(
        url + query, additional_headers={"Authorization": f"Bearer {token}"}, ping_interval=None
    )
    frames, pong = _subscription()
    for frame in frames:
        await ws.send(frame.decode())
    async with asyncio.timeout(30):
        while pong not in (await ws.recv(decode=False)):
            pass
    return ws


async def _guis(
    url: str, guis: int, admin_url: str, admin_token: str, peer: bool, slow_ms: float
) -> None:
    """GUI process: ``guis`` GUIs (and one slow GUI when ``slow_ms``) read every robot_state."""
    import httpx

    window = [0.0, 0.0]
    latencies: array.array[float] = array.array("d")  # not a list: keeps full GCs cheap
    readers = [_Gui(window, latencies, 0.0) for _ in range(guis)]
    links = [await _open_fast_gui(url, peer, g) for g in readers]
    slow_latencies: array.array[float] = array.array("d")
    tasks = []
    if slow_ms > 0:
        slow = _Gui(window, slow_latencies, slow_ms / 1000)
        readers.append(slow)
        slow_ws = await _open_gui(url, peer, admin_token, SLOW_GUI)
        tasks.append(asyncio.create_task(slow.read_slowly(slow_ws)))
    probe = Probe()
    probe.start(freeze=True)
    print("READY", flush=True)
    start_at = await _read_start_time()
    seconds = await _read_start_time()
    window[0], window[1] = start_at + WARMUP_S, start_at + seconds
    await asyncio.sleep(max(0.0, window[0] - time.time()))
    probe.reset()
    for g in readers:
        g.frames = 0
    received0 = [g.received for g in readers]
    cpu0, t0 = time.process_time(), time.monotonic()
    await asyncio.sleep(max(0.0, window[1] - time.time()))
    cpu_percent = 100 * (time.process_time() - cpu0) / (time.monotonic() - t0)
    frames = [g.frames for g in readers]
    window_received = [g.received - r0 for g, r0 in zip(readers, received0, strict=True)]
    health = probe.report()
    await _read_start_time()  # the robots are done
    for _ in range(300):  # until every GUI has had a quiet second (all delivered), max 60 s
        if all(time.monotonic() - g.last_frame >= 1.0 for g in readers):
            break
        await asyncio.sleep(0.2)
    superseded = {"gui": 0, SLOW_GUI: 0}
    if not peer:
        async with httpx.AsyncClient() as http:
            reply = await http.get(f"{admin_url}/api/hub/clients", params={"token": admin_token})
        for c in reply.json()["clients"]:
            who = SLOW_GUI if c["name"] == SLOW_GUI else "gui"
            if c["name"].startswith("gui") or c["name"] == SLOW_GUI:
                superseded[who] += c["superseded"]
    await _close(links)
    if slow_ms > 0:
        await slow_ws.close()
    for task in tasks:
        task.cancel()
    Probe.full_collection(health)
    normal = readers[:guis]
    result: dict[str, Any] = {
        "received": sum(g.received for g in normal),
        "window_received": sum(window_received[:guis]),
        "frames": sum(frames[:guis]),
        "gaps": sum(g.gaps for g in normal),
        "superseded": superseded["gui"],
        "latency_ms": percentiles([x * 1000 for x in latencies]),
        "latency_samples": len(latencies),
        "cpu_percent": round(cpu_percent, 1),
        "slow_seconds": {k: round(v * 1000) for g in normal for k, v in sorted(g.slow.items())},
        **health,
    }
    if slow_ms > 0:
        slow = readers[-1]
        result["slow_gui"] = {
            "read_delay_ms": slow_ms,
            "received": slow.received,
            "superseded": superseded[SLOW_GUI],
            "frames": frames[-1],
            "latency_ms": percentiles([x * 1000 for x in slow_latencies]),
        }
    print(json.dumps(result), flush=True)


def _worker_main(argv: Sequence[str]) -> None:
    parser = argparse.ArgumentParser(prog="bench.hub_workers")
    sub = parser.add_subparsers(dest="role", required=True)
    s = sub.add_parser("server")
    s.add_argument("--robots", type=int, required=True)
    s.add_argument("--full-app", action="store_true")
    s.add_argument("--peer", choices=PEER_SERVERS)
    s.add_argument("--listener", choices=HUB_LISTENERS, default="picows")
    r = sub.add_parser("robots")
    r.add_argument("--url", required=True)
    r.add_argument("--first", type=int, required=True)
    r.add_argument("--count", type=int, required=True)
    r.add_argument("--rate", type=float, required=True)
    r.add_argument("--peer", action="store_true")
    g = sub.add_parser("guis")
    g.add_argument("--url", required=True)
    g.add_argument("--guis", type=int, required=True)
    g.add_argument("--admin-url", required=True)
    g.add_argument("--admin-token", required=True)
    g.add_argument("--slow-ms", type=float, default=0.0)
    g.add_argument("--peer", action="store_true")
    args = parser.parse_args(argv)
    try:
        import uvloop

        runner: Any = uvloop.run
    except ImportError:  # pragma: no cover - uvloop comes with uvicorn[standard]
        runner = asyncio.run
    if args.role == "server":
        runner(_serve(args.robots, args.full_app, args.peer, args.listener))
    elif args.role == "robots":
        runner(_robots(args.url, args.first, args.count, args.rate, args.peer))
    else:
        runner(
            _guis(args.url, args.guis, args.admin_url, args.admin_token, args.peer, args.slow_ms)
        )


if __name__ == "__main__":
    _worker_main(sys.argv[1:])
