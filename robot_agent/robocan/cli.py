"""``guidebot robocan``: run a master (with the simulated BellBot), analyse a bus log, compare
with CANopen DS402, list the installed drivers."""

from __future__ import annotations

import asyncio
import json
import logging
from pathlib import Path
from typing import Any

import click

__all__ = ["robocan"]


@click.group()
def robocan() -> None:
    """The on-board CAN master and the bandwidth study (docs/robocan.md)."""


@robocan.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--bitrate", type=click.IntRange(min=1), default=1_000_000, show_default=True)
@click.option("--window", type=click.FloatRange(min=0.01), default=1.0, show_default=True)
@click.option("--png", type=click.Path(dir_okay=False, path_type=Path), default=None)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def analyze(log: Path, bitrate: int, window: float, png: Path | None, as_json: bool) -> None:
    """Bandwidth per module in 1 s windows and transmission efficiency of a bus LOG
    (.asc, .blf, candump .log, ...)."""
    from robot_agent.robocan.analysis import analyze_log, plot

    try:
        result = analyze_log(log, bitrate=bitrate, window_s=window)
    except Exception as exc:  # the log readers raise anything from ValueError to struct.error
        raise click.ClickException(f"cannot read {log}: {exc}") from None
    if not result["frames"]:
        raise click.ClickException(f"no CAN frames in {log}")
    if png is not None:
        plot(result, png, title=log.name)
    if as_json:
        click.echo(json.dumps(result))
        return
    click.echo(
        f"{result['frames']} frames over {result['duration_s']} s; bus load "
        f"{100 * result['bus_load']['mean']:.2f}% (peak {100 * result['bus_load']['peak']:.2f}%)"
        f"; efficiency {result['efficiency']} (ceiling {result['efficiency_ceiling']})"
    )
    for name, usage in result["modules"].items():
        click.echo(
            f"  {name:>9}: tx {usage['tx_bps']:9.1f} bit/s  rx {usage['rx_bps']:9.1f} bit/s  "
            f"efficiency tx {usage['efficiency']['tx']} rx {usage['efficiency']['rx']}"
        )


@robocan.command()
@click.option(
    "--seconds",
    type=click.FloatRange(min=1.5),
    default=3.0,
    show_default=True,
    help="Length of each phase (moving, stopped); measured over whole half seconds after 0.5 s.",
)
@click.option("--png", type=click.Path(dir_okay=False, path_type=Path), default=None)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object as the last line.")
def compare(seconds: float, png: Path | None, as_json: bool) -> None:
    """BellBot motor profile with RoboCAN and with CANopen DS402 (canopen package)."""
    from robot_agent.robocan.compare import compare as run_compare
    from robot_agent.robocan.compare import plot_compare

    result = asyncio.run(run_compare(seconds))
    if png is not None:
        plot_compare(result, png)
    if not as_json:
        for phase in ("moving", "stopped"):
            r = result[phase]
            click.echo(
                f"{phase:>8}: RoboCAN {r['robocan_bps']:.0f} bit/s, CANopen "
                f"{r['canopen_bps']:.0f} bit/s per motor controller: {100 * r['saving']:.1f}% less"
            )
        click.echo(f"efficiency: {result['efficiency']} (paper: about 6% and 25% less)")
    click.echo(json.dumps(result))


@robocan.command()
@click.option(
    "--bus",
    "buses",
    multiple=True,
    default=["virtual:R1"],
    show_default=True,
    help="python-can bus, e.g. virtual:R1 or socketcan:can0 (repeatable).",
)
@click.option("--simulate/--no-simulate", default=True, show_default=True)
@click.option("--time-scale", type=click.FloatRange(min=0.01), default=1.0, show_default=True)
@click.option("--seconds", type=click.FloatRange(min=0.1), default=10.0, show_default=True)
@click.option("--move", type=float, default=0.0, help="Drive at this speed (m/s) meanwhile.")
@click.option(
    "--record",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Record the bus (.asc, .blf, .log).",
)
def run(
    buses: tuple[str, ...],
    simulate: bool,
    time_scale: float,
    seconds: float,
    move: float,
    record: Path | None,
) -> None:
    """Run the master (and the simulated BellBot) for a while; print its counters and module
    table (kind, firmware, state, counters), then the same as one JSON line."""
    import can

    from guidebot.bus import Bus
    from robot_agent.robocan.busopen import BusSpecError
    from robot_agent.robocan.stack import RoboCanStack

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

    async def main() -> None:
        bus = Bus()
        endpoint, operator = bus.endpoint("robocan"), bus.endpoint("operator")
        operator.subscribe("module_status", lambda m: click.echo(f"module_status {m.payload}"))
        operator.subscribe("base_fault", lambda m: click.echo(f"base_fault {m.payload}"))
        async with RoboCanStack(
            endpoint, list(buses), simulate=simulate, time_scale=time_scale, record=record
        ) as stack:
            if simulate:
                await stack.wait_online()
            if move:
                operator.publish("set_velocity", {"v": move, "w": 0.0})
            await asyncio.sleep(seconds)
            operator.publish("set_velocity", {"v": 0.0, "w": 0.0})
            status = stack.status()
            for line in status_lines(status):
                click.echo(line)
            click.echo(json.dumps(status))

    try:
        asyncio.run(main())
    except (BusSpecError, ValueError, OSError, can.CanError) as exc:
        raise click.ClickException(str(exc)) from None


@robocan.command()
@click.option("--can", "bus", required=True, help="The module's bus: socketcan:can0, virtual:X...")
@click.option("--id", "module_id", required=True, help="The module's ID (even), e.g. 0x40.")
@click.option("--json", "as_json", is_flag=True, help="Also print the checks as one JSON line.")
@click.option(
    "--simulate",
    is_flag=True,
    help="Check our own simulated module of that ID (BellBot set) on a virtual bus.",
)
@click.option(
    "--flaw",
    "flaws",
    multiple=True,
    help="With --simulate: build the module with this deliberate defect (repeatable).",
)
def conformance(
    bus: str, module_id: str, as_json: bool, simulate: bool, flaws: tuple[str, ...]
) -> None:
    """Check a module against docs/robocan.md: a table of checks with the spec section of
    each, then the JSON line {"checks", "passed", "failed": [names]}. Exit status 1 when a
    check fails."""
    from robot_agent.robocan.busopen import BusOpenError, BusSpecError, parse_bus_spec
    from robot_agent.robocan.conformance import run_conformance, summary
    from robot_agent.robocan.sim import BELLBOT, FLAWS, Simulator

    try:
        number = int(module_id, 0)
    except ValueError:
        raise click.BadParameter(f"{module_id!r} is not a number", param_hint="--id") from None
    unknown = set(flaws) - set(FLAWS)
    if unknown:
        known = ", ".join(f"{k} ({v})" for k, v in FLAWS.items())
        raise click.BadParameter(f"unknown {sorted(unknown)}; known: {known}", param_hint="--flaw")
    if flaws and not simulate:
        raise click.UsageError("--flaw needs --simulate")

    async def main() -> list[Any]:
        simulator = None
        if simulate:
            if parse_bus_spec(bus)[0] != "virtual":
                raise click.UsageError("--simulate needs a virtual bus, e.g. --can virtual:conf")
            if number not in BELLBOT:
                ids = ", ".join(f"0x{i:02X}" for i in BELLBOT)
                raise click.UsageError(f"no simulated module 0x{number:02X}; BellBot has {ids}")
            simulator = Simulator(
                bus, layout={number: BELLBOT[number]}, flaws={number: frozenset(flaws)}
            )
            await simulator.start()
        try:
            return await run_conformance(bus, number)
        finally:
            if simulator is not None:
                await simulator.stop()

    try:
        results = asyncio.run(main())
    except (BusSpecError, BusOpenError, ValueError) as exc:
        raise click.ClickException(str(exc)) from None
    width = max(len(r.name) for r in results)
    for r in results:
        verdict = "pass" if r.passed else "FAIL"
        click.echo(f"{r.name:<{width}}  §{r.section:<24} {verdict}  {r.detail}")
    if as_json:
        click.echo(json.dumps([r.__dict__ for r in results]))
    result = summary(results)
    click.echo(json.dumps(result))
    if result["failed"]:
        raise SystemExit(1)


def status_lines(status: dict[str, Any]) -> list[str]:
    """The master's public face as text: per bus its counters, then one line per module."""
    lines = []
    for bus in status["buses"]:
        counters = ", ".join(f"{k} {v}" for k, v in bus["counters"].items())
        lines.append(f"bus {bus['bus']}: {counters}")
        for m in bus["modules"]:
            lines.append(
                f"  0x{m['module_id']:02X} {m['name']:<22} {m['kind'] or '?':<16} "
                f"fw {m['firmware'] or '?':<5} {m['state']:<11} rx {m['frames_rx']} "
                f"tx {m['frames_tx']} errors {m['errors']} faults {m['faults']} "
                f"lost {m['lost']} requeried {m['requeried']}"
            )
    return lines


@robocan.command()
def drivers() -> None:
    """The drivers by element kind: built in, or from the guidebot.robocan_drivers entry
    points. A driver that cannot be loaded is listed with its error; exit status 1 then."""
    from robot_agent.robocan.drivers import DriverRegistry, UnknownDriver

    registry = DriverRegistry()
    broken = False
    for kind in registry.kinds:
        try:
            cls = registry.driver_class(kind)
        except UnknownDriver as exc:
            click.echo(f"{kind:>16}: BROKEN {exc}")
            broken = True
            continue
        critical = " (critical)" if cls.critical else ""
        source = registry.source(kind)
        click.echo(f"{kind:>16}: {cls.__module__}.{cls.__qualname__}{critical} [{source}]")
    if broken:
        raise SystemExit(1)
