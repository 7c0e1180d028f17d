"""``guidebot bench reaction``: the GuideBot paper's reaction-time experiment (section 7.1).

A real fleet on loopback at time scale 1: the central server in its own process, the building
simulator's Modbus/TCP module (in this process, so that T1 is the exact instant the input is
set), and ``--robots`` robot agent processes with simulated RoboCAN hardware, all connected.
Each run presses one of two building buttons (alternately, after a random pause so the press
falls anywhere in the poll period); the button's configured reaction is a ``go_to`` task that
the Task Manager gives to the nearest robot. The server joins the chain's stamps
(``reaction_measured``, docs/reaction.md); this benchmark adds T1 and cancels the task once the
robot moves. One clock: every process runs on this machine, so their time.time() stamps compare.

Prints a table like the paper's Table 2 with the paper's figures beside ours, then the JSON line
{"runs", "robots", "steps", "end_to_end_ms", "overhead_ms", "paper_avg_ms"}; ``--png`` draws a
figure like Figure 17, ``--csv`` writes every run's stamps and steps.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import logging
import random
import statistics
import tempfile
import time
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import Any

import click
import httpx
import yaml

from backend.metrics.reaction import STEPS, steps_ms
from bench.robot import _server_process
from guidebot.benchutil import percentiles, print_result
from guidebot.processes import guidebot_command

PAPER_ROWS: tuple[tuple[str, float, float, float, float | None], ...] = (
    # Table 2 of the paper: average, max, min, deviation (ms). The Modbus row is analytical
    # (uniform wait over a 200 ms poll); its deviation is not printed in the paper.
    ("Modbus", 100.0, 200.0, 0.0, None),
    ("Traffic Manager", 122.67, 245.0, 1.0, 71.92),
    ("Task Manager", 123.54, 309.0, 4.0, 76.82),
    ("RG Recv. PN", 329.19, 453.0, 205.0, 73.09),
    ("RG Req. Path", 415.9, 582.0, 283.0, 74.69),
    ("Get Path", 125.15, 250.0, 3.0, 72.55),
    ("Robot Wi-Fi Int.", 376.23, 504.0, 253.0, 73.93),
    ("Robot moves", 772.11, 1856.0, 433.0, 213.46),
)
PAPER_AVG_MS = 2365  # the sum of the averages: 2364.79 ms
ROBOT_STEPS = ("rg_start", "req_path", "get_path", "command", "can")

# Our steps summed into each of the paper's rows, for the side-by-side table and the figure.
# The paper's server-side RoboGraph rows (Req. Path, Get Path) run on the robot in ours, so they
# are part of our "Robot moves"; the filter sits in the BuildingInterface, before T2, and is
# shown against Recv. PN, which includes the paper's filter.
OURS_FOR_PAPER: dict[str, tuple[str, ...]] = {
    "Modbus": ("modbus_wait",),
    "Traffic Manager": (),
    "Task Manager": ("task_manager",),
    "RG Recv. PN": ("filter",),
    "RG Req. Path": (),
    "Get Path": (),
    "Robot Wi-Fi Int.": ("link",),
    "Robot moves": ROBOT_STEPS,
}
BUTTONS = ("button_west", "button_east")


def bench_site(robots: int, period_ms: int, modbus_port: int) -> dict[str, Any]:
    """A corridor of nodes 3 m apart, a robot on each inner node, a button at each end whose
    reaction sends the nearest robot there. No stations or wait points: idle robots stay."""
    count = robots + 2
    nodes = [{"id": f"c{i}", "floor": "F0", "x": 3.0 * i, "y": 0.0} for i in range(count)]
    edges = [{"a": f"c{i}", "b": f"c{i + 1}"} for i in range(count - 1)]
    ends = {"button_west": "c0", "button_east": f"c{count - 1}"}
    return {
        "name": "Reaction bench",
        "version": 1,
        "floors": [{"id": "F0", "name": "Ground", "level": 0}],
        "nodes": nodes,
        "edges": edges,
        "robots": [
            {"name": f"R{i}", "token": f"robot-R{i}-bench-token", "start_node": f"c{i}"}
            for i in range(1, robots + 1)
        ],
        "modules": [
            {
                "id": "otb",
                "host": "127.0.0.1",
                "port": modbus_port,
                "unit_id": 1,
                "sampling_period_ms": period_ms,
                "points": [
                    {"name": b, "address": i + 1, "kind": "discrete_input", "node": ends[b]}
                    for i, b in enumerate(BUTTONS)
                ],
            }
        ],
        "buttons": [
            {
                "id": b,
                "node": ends[b],
                "input": {"module": "otb", "point": b},
                "task": {"kind": "go_to", "params": {"node": ends[b]}, "priority": 5},
            }
            for b in BUTTONS
        ],
    }


@contextlib.asynccontextmanager
async def _robots(
    url: str, site: Path, count: int, time_scale: float = 1.0
) -> AsyncIterator[list[Any]]:
    """``count`` robot processes with simulated RoboCAN, each printing its ready line."""
    children = []
    try:
        for i in range(1, count + 1):
            args = guidebot_command("robot", "--name", f"R{i}")
            args += ["--server", url, "--token", f"robot-R{i}-bench-token", "--simulate"]
            args += ["--site", str(site), "--log-level", "warning"]
            if time_scale != 1.0:
                args += ["--time-scale", f"{time_scale:g}"]
            children.append(
                await asyncio.create_subprocess_exec(
                    *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL
                )
            )
        for child in children:
            assert child.stdout is not None
            line = await asyncio.wait_for(child.stdout.readline(), 300)
            if b"ready" not in line:
                raise RuntimeError(f"a robot process did not start: {line!r}")
        yield children
    finally:
        for child in children:
            if child.returncode is None:
                child.terminate()
        for child in children:
            try:
                await asyncio.wait_for(child.wait(), 15)
            except TimeoutError:
                child.kill()
                await child.wait()


async def _wait_fleet(http: httpx.AsyncClient, count: int) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        robots = (await http.get("/api/robots")).json()
        if sum(1 for r in robots if r["online"] and r["node"]) == count:
            return
        await asyncio.sleep(0.2)
    raise RuntimeError(f"not all {count} robots came online within 120 s")


async def _experiment(
    runs: int, robots: int, period_ms: int, press_ms: float, seed: int
) -> list[dict[str, float]]:
    from building_sim.simulator import BuildingSimulator
    from guidebot.client import HubClient
    from guidebot.messages import Message
    from guidebot.site.building_config import load_building
    from robot_agent.agent import hub_ws_url

    rng = random.Random(seed)
    records: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-reaction-") as tmp:
        data = bench_site(robots, period_ms, 0)
        sim = BuildingSimulator(load_building(data), time_scale=1.0, port_zero=True)
        async with sim:
            data["modules"][0]["port"] = sim.ports["otb"]
            site = Path(tmp) / "site.yaml"
            site.write_text(yaml.safe_dump(data))
            async with (
                _server_process(tmp, site) as server,
                _robots(server.url, site, robots),
                httpx.AsyncClient(
                    base_url=server.url,
                    headers={"Authorization": f"Bearer {server.admin_token}"},
                    timeout=10,
                ) as http,
            ):
                await _wait_fleet(http, robots)
                hub = HubClient(hub_ws_url(server.url), server.admin_token)
                measured: asyncio.Queue[Message] = asyncio.Queue()
                hub.subscribe("reaction_measured", measured.put_nowait)
                await hub.start()
                try:
                    await hub.sync()
                    for run in range(runs):
                        records.append(
                            await _one_run(sim, http, measured, BUTTONS[run % 2], press_ms, rng)
                        )
                finally:
                    await hub.close()
    return records


async def _one_run(
    sim: Any,
    http: httpx.AsyncClient,
    measured: asyncio.Queue[Any],
    button: str,
    press_ms: float,
    rng: random.Random,
) -> dict[str, float]:
    await asyncio.sleep(rng.uniform(0.1, 0.5))  # a random phase against the poll grid
    pressed_at = time.time()
    sim.press(button, press_ms)
    deadline = time.monotonic() + 15
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise RuntimeError(f"{button}: no robot moved within 15 s of the press")
        message = await asyncio.wait_for(measured.get(), left)
        if message.payload.get("button") == button and "sampled_at" in message.payload["stamps"]:
            break
    stamps = {"pressed_at": pressed_at, **message.payload["stamps"]}
    task_id = message.payload["task_id"]
    (await http.post(f"/api/tasks/{task_id}/cancel", json={"reason": "bench"})).raise_for_status()
    # The robot stops; the button is released and seen released before it is pressed again.
    for _ in range(100):
        task = (await http.get(f"/api/tasks/{task_id}")).json()
        if task["state"] in ("cancelled", "done", "failed"):
            break
        await asyncio.sleep(0.05)
    await asyncio.sleep(max(0.0, pressed_at + press_ms / 1000 - time.time()))
    return stamps


def _stats(values: Sequence[float]) -> dict[str, float]:
    return {
        "avg": round(statistics.fmean(values), 2),
        "max": round(max(values), 2),
        "min": round(min(values), 2),
        "dev": round(statistics.pstdev(values), 2),
    }


def summarise(records: list[dict[str, float]], robots: int) -> dict[str, Any]:
    """The JSON result (the issue's keys) from every run's stamps."""
    per_run = [steps_ms(r) for r in records]
    steps = {s.name: _stats([p[s.name] for p in per_run]) for s in STEPS}
    end_to_end = [(r["moving_at"] - r["pressed_at"]) * 1000 for r in records]
    overhead = [
        e - p["modbus_wait"] - p["filter"] for e, p in zip(end_to_end, per_run, strict=True)
    ]
    return {
        "runs": len(records),
        "robots": robots,
        "steps": steps,
        "end_to_end_ms": {
            **percentiles(end_to_end, digits=2),
            "avg": round(statistics.fmean(end_to_end), 2),
        },
        "overhead_ms": percentiles(overhead, digits=2),
        "paper_avg_ms": PAPER_AVG_MS,
    }


def ours_by_paper_row(steps: dict[str, dict[str, float]]) -> dict[str, float | None]:
    """Our average for each row of the paper's Table 2 (None: no such step in ours)."""
    return {
        row: (round(sum(steps[s]["avg"] for s in ours), 2) if ours else None)
        for row, ours in OURS_FOR_PAPER.items()
    }


def table(result: dict[str, Any], period_ms: int) -> str:
    steps = result["steps"]
    lines = [
        f"Reaction to a building button, {result['runs']} runs, {result['robots']} robots "
        f"connected, poll period {period_ms} ms, filter 200 ms timed from the first changed "
        "sample (ms)",
        "",
        f"{'step':<13}{'paper step':<46}{'avg':>9}{'max':>9}{'min':>9}{'dev':>9}",
    ]
    for s in STEPS:
        v = steps[s.name]
        lines.append(
            f"{s.name:<13}{s.paper:<46}{v['avg']:>9.2f}{v['max']:>9.2f}{v['min']:>9.2f}"
            f"{v['dev']:>9.2f}"
        )
    e2e, over = result["end_to_end_ms"], result["overhead_ms"]
    lines += [
        f"{'end to end':<59}avg {e2e['avg']:.2f}  p50 {e2e['p50']:.2f}  p99 {e2e['p99']:.2f}",
        f"{'overhead (end to end - modbus_wait - filter)':<59}p50 {over['p50']:.2f}  "
        f"p99 {over['p99']:.2f}",
        "",
        "Table 2 of the paper beside ours (averages, ms; '-' : no such step in ours)",
        f"{'paper row':<18}{'paper avg':>10}{'max':>8}{'min':>8}{'dev':>8}{'ours avg':>10}"
        "  our steps",
    ]
    ours = ours_by_paper_row(steps)
    for row, avg, mx, mn, dev in PAPER_ROWS:
        dev_text = "-" if dev is None else f"{dev:.2f}"
        mine = ours[row]
        lines.append(
            f"{row:<18}{avg:>10.2f}{mx:>8.0f}{mn:>8.0f}{dev_text:>8}"
            f"{'-' if mine is None else f'{mine:.2f}':>10}  {' + '.join(OURS_FOR_PAPER[row])}"
        )
    lines.append(f"{'total':<18}{PAPER_AVG_MS:>10.2f}{'':>24}{e2e['avg']:>10.2f}")
    return "\n".join(lines)


def figure(result: dict[str, Any], path: Path) -> None:
    """Figure 17 of the paper: time per module, the paper's series and ours."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r[0] for r in PAPER_ROWS]
    ours = ours_by_paper_row(result["steps"])
    fig, ax = plt.subplots(figsize=(9, 4.5))
    ax.plot(rows, [r[1] for r in PAPER_ROWS], "o-", color="green", label="paper (Core i3 server)")
    ax.plot(rows, [ours[r] or 0.0 for r in rows], "s-", color="tab:blue", label="GuideBot (ours)")
    ax.set_ylabel("average time (ms)")
    ax.set_title(
        f"Reaction to a building sensor: paper {PAPER_AVG_MS} ms, "
        f"ours {result['end_to_end_ms']['avg']:.0f} ms end to end"
    )
    ax.tick_params(axis="x", rotation=30)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_csv(records: list[dict[str, float]], path: Path) -> None:
    from backend.metrics.reaction import STAMPS

    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["run", *STAMPS, *(f"{s.name}_ms" for s in STEPS)])
        for run, stamps in enumerate(records, 1):
            steps = steps_ms(stamps)
            writer.writerow(
                [run, *(stamps.get(n, "") for n in STAMPS), *(steps[s.name] for s in STEPS)]
            )


@click.command()
@click.option("--runs", type=click.IntRange(min=1), default=100, show_default=True)
@click.option("--robots", type=click.IntRange(min=1, max=100), default=20, show_default=True)
@click.option(
    "--period-ms",
    type=click.IntRange(min=20, max=2000),
    default=200,
    show_default=True,
    help="Modbus poll period (the paper's 200 ms); try 150 to see the filter's granularity.",
)
@click.option("--press-ms", type=click.FloatRange(min=1), default=700.0, show_default=True)
@click.option("--seed", type=int, default=1, show_default=True)
@click.option("--png", type=click.Path(dir_okay=False, path_type=Path), default=None)
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path), default=None)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(
    runs: int,
    robots: int,
    period_ms: int,
    press_ms: float,
    seed: int,
    png: Path | None,
    csv_path: Path | None,
    as_json: bool,
) -> None:
    """Building button -> first moving CAN frame, step by step (paper Tables 1-2, Figure 17)."""
    logging.basicConfig(level=logging.ERROR)
    if press_ms < 200 + period_ms:
        raise click.UsageError(
            f"--press-ms {press_ms:g} is too short: a press must outlast the 200 ms filter "
            f"plus a poll period ({200 + period_ms} ms) to be seen for sure"
        )
    records = asyncio.run(_experiment(runs, robots, period_ms, press_ms, seed))
    result = summarise(records, robots)
    if not as_json:
        click.echo(table(result, period_ms))
    if png is not None:
        figure(result, png)
    if csv_path is not None:
        write_csv(records, csv_path)
    with contextlib.suppress(BrokenPipeError):
        print_result(result)
