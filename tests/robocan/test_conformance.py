"""The conformance kit: every simulated BellBot module passes it; modules built with
deliberate flaws fail exactly the checks those flaws break; the command line's contract."""

from __future__ import annotations

import asyncio
import json
import time

from click.testing import CliRunner, Result

from guidebot.cli import main
from robot_agent.robocan.conformance import CHECKS, run_conformance, summary
from robot_agent.robocan.sim import BELLBOT, Simulator


async def _check(module_id: int, flaws: frozenset[str] = frozenset()) -> dict[str, object]:
    channel = f"virtual:conformance-{module_id:02x}-{'-'.join(sorted(flaws))}-{time.monotonic_ns()}"
    simulator = Simulator(channel, layout={module_id: BELLBOT[module_id]}, flaws={module_id: flaws})
    await simulator.start()
    try:
        results = await run_conformance(channel, module_id)
    finally:
        await simulator.stop()
    assert [r.name for r in results] == ["master_bring_up", *(name for name, _, _ in CHECKS)]
    assert all(r.section for r in results)
    return summary(results) | {"details": {r.name: r.detail for r in results}}


def _cli(*args: str) -> Result:
    return CliRunner().invoke(main, ["robocan", "conformance", *args])


async def test_bellbot_passes_and_flawed_modules_fail_what_they_break() -> None:
    """All at once (each run waits on the bus most of the time): the six BellBot modules, two
    flawed ones, and the command line with a flawed module in a thread of its own."""
    flawed = {
        0x02: frozenset({"accepts_any_value", "no_command_timeout"}),
        0x40: frozenset({"answers_broadcast", "no_state_on_enable"}),
    }
    cli = asyncio.to_thread(
        _cli,
        "--can",
        "virtual:conf-cli",
        "--id",
        "0x04",
        "--simulate",
        "--json",
        "--flaw",
        "no_command_timeout",
    )
    *outcomes, cli_result = await asyncio.gather(
        *(_check(module_id) for module_id in BELLBOT),
        *(_check(module_id, flaws) for module_id, flaws in flawed.items()),
        cli,
    )
    good, bad = outcomes[: len(BELLBOT)], outcomes[len(BELLBOT) :]
    for module_id, outcome in zip(BELLBOT, good, strict=True):
        assert outcome["failed"] == [], (hex(module_id), outcome)
        assert outcome["checks"] == outcome["passed"] == len(CHECKS) + 1
    assert bad[0]["failed"] == ["parameters", "command_timeout"]
    assert bad[1]["failed"] == ["enable_and_state_report", "broadcast_id"]

    assert cli_result.exit_code == 1, cli_result.output
    lines = cli_result.output.strip().splitlines()
    assert json.loads(lines[-1]) == {
        "checks": len(CHECKS) + 1,
        "passed": len(CHECKS),
        "failed": ["command_timeout"],
    }
    table = json.loads(lines[-2])
    assert {row["name"]: row["section"] for row in table}["command_timeout"].startswith("6")
    assert any(line.startswith("command_timeout") and " FAIL " in line for line in lines)


def test_the_command_line_refuses_what_it_cannot_do() -> None:
    result = _cli("--can", "virtual:x", "--id", "0x40", "--flaw", "no_command_timeout")
    assert result.exit_code == 2 and "--flaw needs --simulate" in result.output
    result = _cli("--can", "virtual:x", "--id", "0x40", "--simulate", "--flaw", "wobbly")
    assert result.exit_code == 2 and "accepts_any_value" in result.output
    result = _cli("--can", "socketcan:can0", "--id", "0x40", "--simulate")
    assert result.exit_code == 2 and "virtual bus" in result.output
    result = _cli("--can", "virtual:x", "--id", "0x42", "--simulate")
    assert result.exit_code == 2 and "no simulated module 0x42" in result.output
    result = _cli("--can", "virtual:x", "--id", "0x41")
    assert result.exit_code == 1 and "not an even ID" in result.output
    result = _cli("--can", "virtual:x", "--id", "forty")
    assert result.exit_code == 2 and "not a number" in result.output
