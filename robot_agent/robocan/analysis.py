"""The paper's bandwidth study (section 8) over a recorded bus log: per module, bits per
second in 1 s windows (transmitted on its even ID, received on ID + 1), and transmission
efficiency (payload bits over frame bits). Frame lengths are exact (stuff bits computed from
the real CRC) with the 3-bit interframe space counted.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can

from robot_agent.robocan.framebits import EFFICIENCY_CEILING, frame_bits, unstuffed_bits

__all__ = ["Usage", "analyze", "analyze_log", "owner", "plot", "read_log"]

FRAME_LENGTH_NOTE = "exact: stuff bits from the real CRC-15, 3-bit interframe space counted"


def owner(can_id: int) -> tuple[str, str]:
    """Which module a frame belongs to and its direction as seen from the module."""
    if can_id == 0x01:
        return "broadcast", "rx"
    if can_id == 0:
        return "0x00", "tx"
    module = can_id & ~1
    return f"0x{module:02X}", "tx" if can_id % 2 == 0 else "rx"


@dataclass
class Usage:
    """Traffic of one module (or of the whole bus)."""

    frames: dict[str, int] = field(default_factory=lambda: {"tx": 0, "rx": 0})
    bits: dict[str, int] = field(default_factory=lambda: {"tx": 0, "rx": 0})
    unstuffed: dict[str, int] = field(default_factory=lambda: {"tx": 0, "rx": 0})
    payload: dict[str, int] = field(default_factory=lambda: {"tx": 0, "rx": 0})
    windows: dict[int, dict[str, int]] = field(
        default_factory=lambda: defaultdict(lambda: {"tx": 0, "rx": 0})
    )

    def add(self, direction: str, window: int, bits: int, payload: int, n: int) -> None:
        self.frames[direction] += 1
        self.bits[direction] += bits
        self.unstuffed[direction] += unstuffed_bits(n)
        self.payload[direction] += payload
        self.windows[window][direction] += bits

    def efficiency(self, direction: str | None = None) -> float | None:
        keys = [direction] if direction else ["tx", "rx"]
        bits = sum(self.bits[k] for k in keys)
        return round(sum(self.payload[k] for k in keys) / bits, 4) if bits else None


def read_log(path: str | Path) -> list[can.Message]:
    """Any python-can log format (.asc, .blf, .log, .csv, ...), picked by suffix."""
    with can.LogReader(str(path)) as reader:
        return [msg for msg in reader if not msg.is_error_frame]


def analyze(
    messages: Iterable[can.Message],
    *,
    bitrate: int = 1_000_000,
    window_s: float = 1.0,
    start: float | None = None,
    end: float | None = None,
) -> dict[str, Any]:
    """Bandwidth per module and efficiency; times are relative to the first frame."""
    if bitrate <= 0:
        raise ValueError("bitrate must be positive")
    frames = sorted(
        (m for m in messages if not m.is_error_frame and not m.is_extended_id),
        key=lambda m: m.timestamp,
    )
    t0 = frames[0].timestamp if frames else 0.0
    if start is not None or end is not None:
        frames = [
            m
            for m in frames
            if (start is None or m.timestamp - t0 >= start)
            and (end is None or m.timestamp - t0 < end)
        ]
    modules: dict[str, Usage] = defaultdict(Usage)
    bus = Usage()
    for msg in frames:
        data = bytes(msg.data) if not msg.is_remote_frame else b""
        bits = frame_bits(msg.arbitration_id, data, remote=msg.is_remote_frame)
        window = math.floor((msg.timestamp - t0) / window_s)
        name, direction = owner(msg.arbitration_id)
        modules[name].add(direction, window, bits, 8 * len(data), len(data))
        bus.add(direction, window, bits, 8 * len(data), len(data))
    if frames:
        first = start if start is not None else 0.0
        last = end if end is not None else frames[-1].timestamp - t0
        duration = max(window_s, last - first)
    else:
        duration = window_s
    total_bits = sum(bus.bits.values())
    peak = max((sum(w.values()) for w in bus.windows.values()), default=0) / window_s
    return {
        "bitrate": bitrate,
        "frames": len(frames),
        "duration_s": round(duration, 3),
        "frame_length": FRAME_LENGTH_NOTE,
        "bus_load": {
            "mean": round(total_bits / duration / bitrate, 5),
            "peak": round(peak / bitrate, 5),
        },
        "efficiency": bus.efficiency(),
        "efficiency_unstuffed": round(sum(bus.payload.values()) / sum(bus.unstuffed.values()), 4)
        if frames
        else None,
        "efficiency_ceiling": round(EFFICIENCY_CEILING, 4),
        "modules": {
            name: {
                "tx_bps": round(usage.bits["tx"] / duration, 1),
                "rx_bps": round(usage.bits["rx"] / duration, 1),
                "bps": round((usage.bits["tx"] + usage.bits["rx"]) / duration, 1),
                "tx_frames": usage.frames["tx"],
                "rx_frames": usage.frames["rx"],
                "efficiency": {
                    "tx": usage.efficiency("tx"),
                    "rx": usage.efficiency("rx"),
                    "all": usage.efficiency(),
                },
                "windows": [
                    [round(w * window_s, 3), bits["tx"] / window_s, bits["rx"] / window_s]
                    for w, bits in sorted(usage.windows.items())
                ],
            }
            for name, usage in sorted(modules.items())
        },
    }


def analyze_log(path: str | Path, **kwargs: Any) -> dict[str, Any]:
    return analyze(read_log(path), **kwargs)


def plot(result: dict[str, Any], png: str | Path, *, title: str = "RoboCAN bus") -> None:
    """Bandwidth per module over time, transmitted and received (like the paper's Figure 9)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modules = result["modules"]
    fig, axes = plt.subplots(
        len(modules) or 1, 1, figsize=(8, 1.8 * max(1, len(modules))), sharex=True, squeeze=False
    )
    for ax, (name, usage) in zip(axes[:, 0], modules.items(), strict=False):
        times = [w[0] for w in usage["windows"]]
        ax.step(times, [w[1] / 1000 for w in usage["windows"]], where="post", label="tx")
        ax.step(times, [w[2] / 1000 for w in usage["windows"]], where="post", label="rx")
        ax.set_ylabel(f"{name}\nkbit/s")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right")
    axes[0, 0].set_title(f"{title} ({result['frame_length']})", fontsize=8)
    axes[-1, 0].set_xlabel("time (s), 1 s windows")
    fig.tight_layout()
    fig.savefig(str(png), dpi=100)
    plt.close(fig)
