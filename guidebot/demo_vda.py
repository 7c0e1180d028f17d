"""The VDA 5050 part of ``guidebot demo``: a private Mosquitto and simulated VDA 5050 vehicles,
added to the demo's copy of the site as robots V1, V2, ... (docs/vda5050.md)."""

from __future__ import annotations

import shutil
import socket
import subprocess
import time
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "add_vda_robots",
    "broker_command",
    "launch_broker",
    "mosquitto_binary",
    "start_broker",
    "wait_broker",
]

START_NODES = ("entrance", "ga2", "gb2", "gc3", "hall")
"""Where the demo's vehicles start, the first ones no started GuideBot robot stands on."""


def mosquitto_binary() -> str | None:
    return shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin:/sbin")


def broker_command(binary: str, folder: Path) -> tuple[list[str], int]:
    """Mosquitto's command line for a free port of 127.0.0.1 (its configuration written in
    ``folder``), and that port. The launcher starts it (``launch_broker``) as one of its
    children, so that it is stopped with them."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    config = folder / "mosquitto.conf"
    config.write_text(
        f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\nlog_dest none\n"
        # Each message passed on at once (Mosquitto leaves Nagle's algorithm on by default).
        "set_tcp_nodelay true\n",
        encoding="utf-8",
    )
    return [binary, "-c", str(config)], port


def launch_broker(command: list[str]) -> subprocess.Popen[bytes]:
    """Mosquitto in a session of its own (Ctrl-C reaches only the launcher), quiet."""
    return subprocess.Popen(
        command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )


def wait_broker(process: subprocess.Popen[bytes], port: int, timeout_s: float = 20.0) -> str:
    """Until the broker listens on ``port``; its mqtt:// address."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"mosquitto exited with {process.returncode}")
        try:
            socket.create_connection(("127.0.0.1", port), 1).close()
        except OSError:
            time.sleep(0.05)
            continue
        return f"mqtt://127.0.0.1:{port}"
    raise RuntimeError(f"mosquitto did not listen on port {port} within {timeout_s:g} s")


def start_broker(binary: str, folder: Path) -> tuple[subprocess.Popen[bytes], str]:
    """Mosquitto on a free port of 127.0.0.1, its configuration in ``folder``; waits until it
    listens (killed if it does not, or the wait is cut short). Returns the process and its
    mqtt:// address."""
    command, port = broker_command(binary, folder)
    process = launch_broker(command)
    try:
        return process, wait_broker(process, port)
    except BaseException:
        process.kill()
        process.wait()
        raise


def add_vda_robots(served: Path, count: int, taken: set[str], version: str = "2.1.0") -> list[str]:
    """Add ``count`` VDA 5050 robots speaking ``version`` to the site file ``served`` (in
    place), each on a start node not in ``taken``; returns their names."""
    data: dict[str, Any] = yaml.safe_load(served.read_text(encoding="utf-8"))
    nodes = {n["id"] for n in data["nodes"]}
    free = [n for n in START_NODES if n in nodes and n not in taken] or [data["nodes"][0]["id"]]
    names = []
    for i in range(1, count + 1):
        name = f"V{i}"
        data["robots"].append(
            {
                "name": name,
                "token": f"robot-{name}-demo-token",
                "start_node": free[(i - 1) % len(free)],
                "interface": "vda5050",
                "manufacturer": "GuideBotSim",
                "serial_number": f"{name}-0001",
                "vda_version": version,
            }
        )
        names.append(name)
    served.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return names
