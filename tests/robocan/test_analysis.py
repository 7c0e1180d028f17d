"""Bandwidth study: per-module bits per second and efficiency, logs in python-can formats
written by the master, the CLI, and the CANopen comparison."""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest
from click.testing import CliRunner

from guidebot.bus import Bus
from guidebot.cli import main
from robot_agent.robocan.analysis import analyze, read_log
from robot_agent.robocan.compare import compare
from robot_agent.robocan.framebits import EFFICIENCY_CEILING, frame_bits
from robot_agent.robocan.stack import RoboCanStack


def synthetic(seconds: int = 3) -> list[can.Message]:
    """Module 0x02 publishes 8 bytes at 10 Hz and receives 7 bytes at 8 Hz; one broadcast."""

    def frame(t: float, can_id: int, data: bytes) -> can.Message:
        return can.Message(timestamp=t, arbitration_id=can_id, data=data, is_extended_id=False)

    frames = [frame(100 + i / 10, 0x02, bytes(8)) for i in range(10 * seconds)]
    frames += [frame(100 + i / 8, 0x03, bytes(7)) for i in range(8 * seconds)]
    frames.append(frame(100.5, 0x01, b"\x94"))
    return frames


def test_per_module_bandwidth_and_efficiency() -> None:
    result = analyze(synthetic(), bitrate=1_000_000, start=0.0, end=3.0)
    module = result["modules"]["0x02"]
    tx_bits, rx_bits = frame_bits(0x02, bytes(8)), frame_bits(0x03, bytes(7))
    assert module["tx_bps"] == pytest.approx(10 * tx_bits, abs=0.1)
    assert module["rx_bps"] == pytest.approx(8 * rx_bits, abs=0.1)
    assert module["tx_frames"] == 30 and module["rx_frames"] == 24
    assert module["efficiency"]["tx"] == pytest.approx(64 / tx_bits, abs=1e-4)
    assert len(module["windows"]) == 3 and module["windows"][0][1] == 10 * tx_bits
    assert result["modules"]["broadcast"]["rx_frames"] == 1
    assert result["efficiency"] < EFFICIENCY_CEILING
    assert result["bus_load"]["mean"] == pytest.approx(
        (30 * tx_bits + 24 * rx_bits + frame_bits(0x01, b"\x94")) / 3 / 1e6, abs=1e-5
    )


def test_bad_bitrate_is_refused() -> None:
    with pytest.raises(ValueError, match="bitrate"):
        analyze(synthetic(), bitrate=0)


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".log"])
async def test_master_records_traffic_in_python_can_formats(
    tmp_path: Path, channel: str, suffix: str
) -> None:
    path = tmp_path / f"bus{suffix}"
    bus = Bus()
    stack = RoboCanStack(bus.endpoint("robocan"), [channel], layout={0x02: "motor"}, record=path)
    async with stack:
        await stack.wait_online()
    frames = read_log(path)
    ids = {f.arbitration_id for f in frames}
    assert {0x01, 0x02, 0x03} <= ids  # master start broadcast, module, its commands
    assert any(f.arbitration_id == 0x03 and f.data[0] == 0x80 for f in frames)  # QUERY
    result = analyze(frames)
    assert result["modules"]["0x02"]["tx_frames"] > 0


def test_cli_analyze_json_and_png(tmp_path: Path) -> None:
    log = tmp_path / "bus.log"
    writer = can.Logger(str(log))
    for msg in synthetic():
        writer.on_message_received(msg)
    writer.stop()
    png = tmp_path / "bus.png"
    result = CliRunner().invoke(main, ["robocan", "analyze", str(log), "--json", "--png", str(png)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output.strip().splitlines()[-1])
    assert set(data["modules"]) == {"0x02", "broadcast"}
    assert png.stat().st_size > 1000


def test_cli_analyze_refuses_unreadable_logs(tmp_path: Path) -> None:
    bad = tmp_path / "bus.log"
    bad.write_text("this is not candump output\n")
    result = CliRunner().invoke(main, ["robocan", "analyze", str(bad), "--json"])
    assert result.exit_code != 0 and "cannot read" in result.output
    empty = tmp_path / "empty.asc"
    empty.write_text("")
    result = CliRunner().invoke(main, ["robocan", "analyze", str(empty)])
    assert result.exit_code != 0 and "no CAN frames" in result.output


async def test_compare_robocan_is_leaner_than_canopen_ds402() -> None:
    result = await compare(phase_s=1.5)
    assert set(result) == {"moving", "stopped", "efficiency"}
    assert set(result["moving"]) == {"robocan_bps", "canopen_bps", "saving"}
    assert 0 < result["moving"]["saving"] < result["stopped"]["saving"]
    assert result["moving"]["robocan_bps"] > result["stopped"]["robocan_bps"]
    assert all(0 < e < EFFICIENCY_CEILING for e in result["efficiency"].values())
