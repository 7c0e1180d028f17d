"""RoboCAN against CANopen DS402 on the BellBot motor profile (the paper's Figure 10 and 11).

Both runs are real traffic on python-can virtual buses, recorded and measured with the same
exact frame lengths: RoboCAN = our master and simulated motor controllers (encoder frames at
10 Hz, velocity commands at 8 Hz while moving, none while stopped, 10 Hz watchdogs); CANopen =
frames built and sent by the ``canopen`` package as a DS402 drive pair and its master would
(TPDO1 position + velocity actual at 10 Hz, RPDO1 controlword + target velocity at 8 Hz, sent
cyclically moving or not, SYNC at 10 Hz, heartbeat at 10 Hz), each on its period's grid
(``_on_grid``), as the RoboCAN modules send.
"""

from __future__ import annotations

import asyncio
import math
import tempfile
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import can
import canopen
from canopen.objectdictionary import (
    INTEGER32,
    UNSIGNED8,
    UNSIGNED16,
    UNSIGNED32,
    ODRecord,
    ODVariable,
)

from guidebot.bus import Bus
from robot_agent.robocan.analysis import read_log
from robot_agent.robocan.busopen import open_bus
from robot_agent.robocan.framebits import frame_bits
from robot_agent.robocan.stack import RoboCanStack

__all__ = ["compare", "ds402_dictionary", "measure", "plot_compare"]

MOTORS = (0x02, 0x04)
PUBLISH_HZ = 10
COMMAND_HZ = 8
SETTLE_S = 0.5  # skip the first half second of each phase (start-up, last command)
MIN_PHASE_S = 1.5
"""The shortest phase with a whole-period window after SETTLE_S (``--seconds``)."""


def _var(name: str, index: int, subindex: int, data_type: int) -> ODVariable:
    var = ODVariable(name, index, subindex)
    var.data_type = data_type
    var.access_type = "rw"
    return var


def ds402_dictionary() -> canopen.ObjectDictionary:
    """The slice of a DS402 drive's object dictionary the PDOs need."""
    od = canopen.ObjectDictionary()
    for base in (0x1400, 0x1600, 0x1800, 0x1A00):
        for n in range(4):
            record = ODRecord(f"pdo_{base + n:04X}", base + n)
            record.add_member(_var("count", base + n, 0, UNSIGNED8))
            for sub in range(1, 9):
                record.add_member(_var(f"sub{sub}", base + n, sub, UNSIGNED32))
            od.add_object(record)
    for index, name, data_type in (
        (0x6040, "controlword", UNSIGNED16),
        (0x6041, "statusword", UNSIGNED16),
        (0x6060, "modes_of_operation", UNSIGNED8),
        (0x6064, "position_actual_value", INTEGER32),
        (0x606C, "velocity_actual_value", INTEGER32),
        (0x60FF, "target_velocity", INTEGER32),
    ):
        od.add_object(_var(name, index, 0, data_type))
    return od


class _Collector(can.Listener):
    def __init__(self) -> None:
        self.frames: list[can.Message] = []
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self.frames.append(msg)


def measure(
    frames: Iterable[can.Message], owner_of: dict[int, int], start: float, end: float, nodes: int
) -> tuple[float, int, int]:
    """Bits per second per node of the frames whose ID ``owner_of`` lists, in [start, end).

    ``owner_of`` maps an ID to a node, or to 0 for frames shared by all nodes (SYNC), which
    are divided among them. Returns (bps per node, payload bits, frame bits).
    """
    bits = payload = 0
    for msg in frames:
        if not start <= msg.timestamp < end or msg.arbitration_id not in owner_of:
            continue
        data = bytes(msg.data)
        bits += frame_bits(msg.arbitration_id, data)
        payload += 8 * len(data)
    return bits / (end - start) / nodes, payload, bits


async def run_robocan(phase_s: float, log_path: Path) -> dict[str, Any]:
    """The real master and two simulated motor controllers, recorded to a candump log."""
    channel = f"virtual:compare-robocan-{time.monotonic_ns()}"
    bus = Bus()
    endpoint, navigation = bus.endpoint("robocan"), bus.endpoint("navigation")
    layout = {0x02: "motor", 0x04: "motor"}
    async with RoboCanStack(endpoint, [channel], layout=layout, record=log_path) as stack:
        await stack.wait_online(set(MOTORS))
        await asyncio.sleep(SETTLE_S)
        t_move = time.time()
        navigation.publish("set_velocity", {"v": 0.5, "w": 0.1})
        await asyncio.sleep(phase_s)
        t_stop = time.time()
        navigation.publish("set_velocity", {"v": 0.0, "w": 0.0})
        await asyncio.sleep(phase_s)
        t_end = time.time()
    frames = read_log(log_path)
    ids = {can_id: 1 for m in MOTORS for can_id in (m, m + 1)}
    return _phases(frames, ids, t_move, t_stop, t_end)


NMT_OPERATIONAL = 0x05
"""A heartbeat's one data byte: the producer's NMT state (CiA 301)."""


def _on_grid(hz: float, send: Callable[[], None]) -> asyncio.Task[None]:
    """Call ``send`` ``hz`` times a second on the period's grid, catching up after a stall as
    a drive's hardware timer and our simulated modules do (python-can's threaded cyclic
    sender, which canopen's ``start`` uses, restarts its period after a late frame: on a loaded
    machine CANopen then sent fewer frames than its schedule and looked as lean as RoboCAN)."""

    async def run() -> None:
        period, start, n = 1 / hz, time.monotonic(), 0
        while True:
            send()
            n += 1
            await asyncio.sleep(max(0.0, start + n * period - time.monotonic()))

    return asyncio.get_running_loop().create_task(run())


def _heartbeat(network: canopen.Network, node_id: int) -> Callable[[], None]:
    """The drive's heartbeat frame (what ``nmt.start_heartbeat`` sends periodically)."""
    return lambda: network.send_message(0x700 + node_id, bytes([NMT_OPERATIONAL]))


WINDOW_GRID_S = 0.5
"""Measured windows last a whole number of half seconds: whole periods of the 10 Hz and 8 Hz
schedules, so each holds the same number of each frame."""
WINDOW_OFFSET_S = 0.04
"""Windows start this long off the schedules' grid (10 Hz and 8 Hz from the phase's start), so
that no frame lands on an edge and is counted or not by a microsecond."""


def _phases(
    frames: list[can.Message], ids: dict[int, int], t_move: float, t_stop: float, t_end: float
) -> dict[str, Any]:
    """Each phase measured over whole periods, after SETTLE_S (start-up, the last command)."""
    usable = min(t_stop - t_move, t_end - t_stop) - SETTLE_S - WINDOW_OFFSET_S
    window = math.floor(usable / WINDOW_GRID_S) * WINDOW_GRID_S
    if window <= 0:
        raise ValueError(f"phases of at least {MIN_PHASE_S} s are needed to measure")
    (moving, p1, b1), (stopped, p2, b2) = (
        measure(frames, ids, start, start + window, len(MOTORS))
        for start in (t + SETTLE_S + WINDOW_OFFSET_S for t in (t_move, t_stop))
    )
    return {"moving": moving, "stopped": stopped, "efficiency": (p1 + p2) / (b1 + b2)}


async def run_canopen(phase_s: float) -> dict[str, Any]:
    """A DS402 master and two drives built with the canopen package, on a virtual bus."""
    channel = f"virtual:compare-canopen-{time.monotonic_ns()}"
    master_bus, drive_bus, tap_bus = (open_bus(channel) for _ in range(3))
    collector = _Collector()
    tap = can.Notifier(tap_bus, [collector], timeout=0.05)
    master_net, drive_net = canopen.Network(master_bus), canopen.Network(drive_bus)
    rpdos, tpdos = [], []
    cyclic: list[asyncio.Task[None]] = []
    try:
        for node_id in MOTORS:
            remote = canopen.RemoteNode(node_id, ds402_dictionary())
            master_net.add_node(remote)
            rpdo = remote.rpdo[1]
            rpdo.clear()
            rpdo.add_variable(0x6040)
            rpdo.add_variable(0x60FF)
            rpdo.cob_id, rpdo.enabled = 0x200 + node_id, True
            rpdo[0x6040].raw = 0x000F  # operation enabled
            rpdo[0x60FF].raw = 0
            rpdos.append(rpdo)

            drive = canopen.LocalNode(node_id, ds402_dictionary())
            drive_net.add_node(drive)
            tpdo = drive.tpdo[1]
            tpdo.clear()
            tpdo.add_variable(0x6064)
            tpdo.add_variable(0x606C)
            tpdo.cob_id, tpdo.enabled = 0x180 + node_id, True
            tpdo[0x6064].raw = 1_234_567  # a drive that has travelled: realistic stuffing
            tpdo[0x606C].raw = 0
            tpdos.append(tpdo)
            drive.nmt.state = "OPERATIONAL"
            cyclic.append(_on_grid(PUBLISH_HZ, tpdo.transmit))
            cyclic.append(_on_grid(PUBLISH_HZ, _heartbeat(drive_net, node_id)))
        cyclic.append(_on_grid(PUBLISH_HZ, master_net.sync.transmit))
        await asyncio.sleep(SETTLE_S)
        t_move = time.time()
        for rpdo in rpdos:
            rpdo[0x60FF].raw = 500_000  # counts/s: moving
            cyclic.append(_on_grid(COMMAND_HZ, rpdo.transmit))
        for tpdo in tpdos:
            tpdo[0x606C].raw = 499_871
        await asyncio.sleep(phase_s)
        t_stop = time.time()
        for rpdo in rpdos:
            rpdo[0x60FF].raw = 0  # a cyclic DS402 master keeps sending its set-point
        for tpdo in tpdos:
            tpdo[0x606C].raw = 0
        await asyncio.sleep(phase_s)
        t_end = time.time()
    finally:
        for task in cyclic:
            task.cancel()
        await asyncio.gather(*cyclic, return_exceptions=True)
        await asyncio.to_thread(tap.stop, 1.0)
        for b in (master_bus, drive_bus, tap_bus):
            b.shutdown()
    ids = {0x080: 0}
    for node_id in MOTORS:
        for base in (0x180, 0x200, 0x700):
            ids[base + node_id] = node_id
    return _phases(collector.frames, ids, t_move, t_stop, t_end)


async def compare(phase_s: float = 3.0) -> dict[str, Any]:
    """Both runs; the result has the issue's keys (bits per second per motor controller)."""
    if phase_s < MIN_PHASE_S:
        raise ValueError(f"phases of at least {MIN_PHASE_S} s are needed to measure")
    with tempfile.TemporaryDirectory() as tmp:
        robocan = await run_robocan(phase_s, Path(tmp) / "robocan.log")
    canopen_result = await run_canopen(phase_s)
    result: dict[str, Any] = {}
    for phase in ("moving", "stopped"):
        r, c = robocan[phase], canopen_result[phase]
        result[phase] = {
            "robocan_bps": round(r, 1),
            "canopen_bps": round(c, 1),
            "saving": round(1 - r / c, 4) if c else None,
        }
    result["efficiency"] = {
        "robocan": round(robocan["efficiency"], 4),
        "canopen": round(canopen_result["efficiency"], 4),
    }
    return result


def plot_compare(result: dict[str, Any], png: str | Path) -> None:
    """Bandwidth per motor controller, moving and stopped, and efficiency (Figures 10, 11)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (bw, eff) = plt.subplots(1, 2, figsize=(9, 3.5), gridspec_kw={"width_ratios": [2, 1]})
    phases = ["moving", "stopped"]
    for offset, (key, label) in enumerate(
        [("robocan_bps", "RoboCAN"), ("canopen_bps", "CANopen DS402")]
    ):
        values = [result[phase][key] / 1000 for phase in phases]
        bw.bar([i + offset * 0.38 for i in range(2)], values, width=0.38, label=label)
    bw.set_xticks([0.19, 1.19], [f"{ph} (-{100 * result[ph]['saving']:.0f}%)" for ph in phases])
    bw.set_ylabel("kbit/s per motor controller")
    bw.legend()
    eff.bar(["RoboCAN", "CANopen"], [100 * v for v in result["efficiency"].values()])
    eff.axhline(100 * 64 / 111, color="grey", linestyle="--", label="ceiling 57.66%")
    eff.set_ylabel("efficiency (%)")
    eff.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(str(png), dpi=100)
    plt.close(fig)
