"""``guidebot robocan conformance``: checks one module on a bus against docs/robocan.md.

Our master first brings the module online with its drivers (the real bring-up); then a probe
that speaks raw frames, as a master would, walks it through the rest of its life cycle:
watchdogs, query and description (with a lost frame and a paused window), parameters, modes,
enable and disable, the commands its element kinds accept with their exact ACKs, publishing
periods, block transfer towards it (gap, time-out, refusals), garbage, the broadcast ID, and
the motor command time-out of a silent master. Each check names its spec section.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import can

from guidebot.bus import Bus
from robot_agent.robocan import protocol as p
from robot_agent.robocan.busopen import BusReader, open_bus
from robot_agent.robocan.master import Master, ModuleState
from robot_agent.robocan.probe import (
    CheckFailed,
    Probe,
    battery_charging,
    expect_status,
    frame_is,
    median_interval,
    near,
    periods,
    servo_at,
)

__all__ = ["CHECKS", "CheckFailed", "Result", "run_conformance"]

K = p.ElementKind


@dataclass
class Result:
    name: str
    section: str
    passed: bool
    detail: str = ""


# --- the checks ---------------------------------------------------------------------------------


@dataclass
class Context:
    probe: Probe
    description: p.Description | None = None
    channel: str = ""

    @property
    def d(self) -> p.Description:
        if self.description is None:
            raise CheckFailed("no description (the query check failed)")
        return self.description

    def numbers(self, *kinds: int) -> list[int]:
        return [i for i, e in enumerate(self.d.elements) if e.kind in kinds]


Check = Callable[[Context], Awaitable[str]]
CHECKS: list[tuple[str, str, Check]] = []


def check(name: str, section: str) -> Callable[[Check], Check]:
    def register(fn: Check) -> Check:
        CHECKS.append((name, section, fn))
        return fn

    return register


@check("watchdog", "4.1, 6")
async def check_watchdog(ctx: Context) -> str:
    probe = ctx.probe
    period = await periods(probe, p.Op.WATCHDOG, None, 5, 2.0)
    near(period, p.WATCHDOG_PERIOD_S, "WATCHDOG")
    bad = [
        f.data for f in probe.frames if f.data[0] <= 0x0F and (len(f.data) != 1 or f.data[0] > 1)
    ]
    if bad:
        raise CheckFailed(f"malformed watchdog frames: {bad[:3]}")
    return f"every {period * 1000:.0f} ms"


@check("master_start", "4.8")
async def check_master_start(ctx: Context) -> str:
    probe = ctx.probe
    mark = probe.mark()
    probe.send(bytes([p.Op.MASTER_START]), can_id=p.BROADCAST_ID)
    await asyncio.sleep(0.01)
    later = probe.mark()
    frame = await probe.expect(later, lambda d: d[0] <= 0x0F, 0.5, "a watchdog")
    if frame.data[0] != p.SlaveState.DISABLED:
        # That one may have been sent before the module read MASTER_START (a busy module, or
        # a loaded machine's simulator): the next one must say DISABLED.
        after = probe.frames.index(frame, later) + 1
        frame = await probe.expect(after, lambda d: d[0] <= 0x0F, 0.5, "a watchdog")
        if frame.data[0] != p.SlaveState.DISABLED:
            raise CheckFailed("still ENABLED after MASTER_START")
    answers = [f.data for f in probe.since(mark) if f.data[0] > 0x0F and f.t < frame.t]
    if any(d[0] == p.Op.ACK for d in answers):
        raise CheckFailed("answered MASTER_START")
    return "DISABLED, no answer"


@check("query_description", "5")
async def check_query(ctx: Context) -> str:
    raw = await ctx.probe.query()
    try:
        ctx.description = p.Description.decode(raw)
    except p.ProtocolError as exc:
        raise CheckFailed(f"bad description: {exc}") from None
    d = ctx.description
    for i, e in enumerate(d.elements):
        if e.kind not in list(K) and e.kind_name.startswith("kind_"):
            continue  # a kind of its own: allowed, no driver
        if e.kind in (K.PID_VELOCITY, K.FIRING_SEQUENCE) and e.role != p.Role.AGENT:
            raise CheckFailed(f"element {i} ({e.kind_name}) must be an agent")
    kinds = ", ".join(e.kind_name for e in d.elements)
    return f"{d.name} kind {d.kind} firmware {d.firmware[0]}.{d.firmware[1]}: {kinds}"


@check("description_lost_frame", "5.3")
async def check_description_gap(ctx: Context) -> str:
    from robot_agent.robocan.blocks import frame_count

    if frame_count(len(ctx.d.encode())) < 2:
        return "description fits in one data frame: nothing to lose"
    if p.Description.decode(await ctx.probe.query(drop=2)) != ctx.d:
        raise CheckFailed("description differs after a resend")
    return "frame 2 lost, resent from 2"


@check("description_flow_window", "5.2, 5.4")
async def check_description_window(ctx: Context) -> str:
    if p.Description.decode(await ctx.probe.query(pause_after=1)) != ctx.d:
        raise CheckFailed("description differs after a paused window")
    return "window of 1 honoured, resumed after 300 ms"


@check("parameters", "3 (parameters)")
async def check_parameters(ctx: Context) -> str:
    probe, d = ctx.probe, ctx.d
    checked = 0
    status = await probe.command(p.set_param(p.MODULE, p.Param.WATCHDOG_MS, 100))
    expect_status(status, p.AckStatus.OK, "WATCHDOG_MS 100")
    status = await probe.command(p.set_param(p.MODULE, p.Param.WATCHDOG_MS, 5))
    expect_status(status, p.AckStatus.BAD_VALUE, "WATCHDOG_MS 5")
    status = await probe.command(p.set_param(p.MODULE, p.Param.PUBLISH_MS, 100))
    expect_status(status, p.AckStatus.BAD_PARAM, "PUBLISH_MS on the module")
    status = await probe.command(p.set_param(len(d.elements), p.Param.PUBLISH_MS, 100))
    expect_status(status, p.AckStatus.UNKNOWN_ELEMENT, "an element beyond the description")
    for i, e in enumerate(d.elements):
        params = p.ELEMENT_PARAMS.get(e.kind, frozenset())
        for param in sorted(params):
            low, high = p.PARAM_RANGES[param]
            for value in (low - 1, high + 1):
                status = await probe.command(p.set_param(i, param, value))
                expect_status(status, p.AckStatus.BAD_VALUE, f"element {i} param {param} = {value}")
            default = (
                p.DEFAULT_PUBLISH_MS[e.kind]
                if param == p.Param.PUBLISH_MS
                else p.PARAM_DEFAULTS.get(param)
            )
            if default is not None:
                status = await probe.command(p.set_param(i, param, default))
                expect_status(status, p.AckStatus.OK, f"element {i} param {param} = {default}")
            checked += 1
        foreign = next(q for q in p.Param if q not in params and q != p.Param.WATCHDOG_MS)
        status = await probe.command(p.set_param(i, foreign, 1))
        expect_status(status, p.AckStatus.BAD_PARAM, f"element {i} param {foreign.name}")
    return f"{checked} parameters in range / out of range, foreign ones refused"


@check("modes", "3 (working modes)")
async def check_modes(ctx: Context) -> str:
    probe, d = ctx.probe, ctx.d
    for i, e in enumerate(d.elements):
        if not e.modes:
            status = await probe.command(p.set_mode(i, 0))
            expect_status(status, p.AckStatus.UNSUPPORTED, f"SET_MODE on element {i} (no modes)")
            continue
        clear = next((m for m in range(8) if not e.modes & (1 << m)), None)
        if clear is not None:
            status = await probe.command(p.set_mode(i, clear))
            expect_status(status, p.AckStatus.BAD_VALUE, f"element {i} mode {clear}")
        status = await probe.command(p.set_mode(i, 0))
        expect_status(status, p.AckStatus.OK, f"element {i} mode 0")
    status = await probe.command(p.set_mode(len(d.elements), 0))
    expect_status(status, p.AckStatus.UNKNOWN_ELEMENT, "SET_MODE beyond the description")
    return f"{len(d.elements)} elements"


async def _enable(ctx: Context, on: bool) -> int:
    mark = ctx.probe.mark()
    status = await ctx.probe.command(p.enable(p.MODULE, on))
    expect_status(status, p.AckStatus.OK, f"ENABLE 0xFF {int(on)}")
    return mark


@check("enable_and_state_report", "3, 4.5")
async def check_enable(ctx: Context) -> str:
    probe = ctx.probe
    for i in ctx.numbers(K.PID_VELOCITY, K.FIRING_SEQUENCE):
        await probe.command(p.set_mode(i, 1))  # velocity control / fire
    mark = await _enable(ctx, True)
    ack = next(f for f in probe.since(mark) if f.data[0] == p.Op.ACK)
    reports = {
        K.BUMPER: p.Op.BUMPERS,
        K.TOUCH: p.Op.INPUTS,
    }
    for i, e in enumerate(ctx.d.elements):
        op = reports.get(K(e.kind)) if e.kind in list(K) else None
        if op is not None:
            await probe.expect(mark, frame_is(op, i), 0.5, f"state of element {i}")
    frame = await probe.expect(probe.mark(), lambda d: d[0] <= 0x0F, 0.5, "a watchdog")
    if frame.data[0] != p.SlaveState.ENABLED:
        raise CheckFailed("watchdog still says DISABLED after ENABLE")
    first = [f.data for f in probe.since(mark) if f.t >= ack.t and f.data[0] in reports.values()]
    return f"ACK {ack.data.hex()}, {len(first)} state frames, watchdog ENABLED"


@check("data_frames", "3, 5 (element numbers)")
async def check_data_frames(ctx: Context) -> str:
    """Every data frame names an element of a kind that sends it; sonar frames cover the
    element's sonars in index order."""
    await asyncio.sleep(0.6)
    frames = [f.data for f in ctx.probe.frames if f.data[0] in p.DATA_KINDS]
    for data in frames:
        element = ctx.d.data_element(data[0], data)
        if element is None:
            raise CheckFailed(f"frame {data.hex()} names no element of a kind that sends it")
        if data[0] == p.Op.SONAR:
            count = ctx.d.elements[element].count
            if data[2] + len(data) - 3 > count:
                raise CheckFailed(f"sonar frame {data.hex()} beyond {count} sonars")
    return f"{len(frames)} data frames"


@check("publish_periods", "3 (PUBLISH_MS)")
async def check_publish(ctx: Context) -> str:
    probe, done = ctx.probe, []
    periodic = {K.MOTOR: p.Op.ENCODER, K.SONAR: p.Op.SONAR, K.BATTERY: p.Op.BATTERY}
    for i, e in enumerate(ctx.d.elements):
        op = periodic.get(K(e.kind)) if e.kind in list(K) else None
        if op is None:
            continue
        status = await probe.command(p.set_param(i, p.Param.PUBLISH_MS, 200))
        expect_status(status, p.AckStatus.OK, f"PUBLISH_MS 200 on element {i}")
        element = None if op == p.Op.BATTERY else i
        if op == p.Op.SONAR:  # several frames per round: time the first one of each round
            mark = probe.mark()
            await asyncio.sleep(1.0)
            starts = [f.t for f in probe.since(mark, op) if f.data[1] == i and f.data[2] == 0]
            if len(starts) < 3:
                raise CheckFailed(f"sonar element {i}: {len(starts)} rounds in 1 s at 200 ms")
            period = median_interval(starts)
        else:
            period = await periods(probe, op, element, 3, 2.0)
        near(period, 0.2, f"element {i}")
        done.append(f"{i}: {period * 1000:.0f} ms")
    return ", ".join(done) or "no periodic data element"


@check("commands", "3 (master to slave)")
async def check_commands(ctx: Context) -> str:
    probe, d, done = ctx.probe, ctx.d, []
    batteries = ctx.numbers(K.BATTERY)
    if batteries:  # a 1 s period, so that a frame within 0.5 s is the one sent "at once"
        await probe.command(p.set_param(batteries[0], p.Param.PUBLISH_MS, 1000))
    for on in (1, 0) if batteries else (1,):
        mark = probe.mark()
        status = await probe.command(bytes([p.Op.SET_CHARGING, on]))
        if not batteries:
            break
        expect_status(status, p.AckStatus.OK, f"SET_CHARGING {on}")
        await probe.expect(
            mark,
            battery_charging(on),
            0.5,
            f"BATTERY with charging = {on} at once after SET_CHARGING {on}",
        )
    if batteries:
        done.append("SET_CHARGING")
    else:
        expect_status(status, p.AckStatus.UNSUPPORTED, "SET_CHARGING without a battery")
    for i in ctx.numbers(K.SERVO):
        for speed in (0.0, 180.0):
            target = 12.5 if speed else -7.5
            mark = probe.mark()
            probe.send(p.set_servo(i, 0, target, speed))
            await probe.expect(
                mark,
                servo_at(i, target),
                3.0,
                f"servo 0 of element {i} in position at {target}° (speed {speed})",
            )
        done.append(f"SET_SERVO element {i}")
    for i in ctx.numbers(K.LED):
        mark = probe.mark()
        probe.send(p.set_output(i, 0, 128))
        if [b for b in await probe.silence(mark) if b[0] == p.Op.ACK]:
            raise CheckFailed("SET_OUTPUT is not acknowledged, but was")
        done.append(f"SET_OUTPUT element {i}")
    if len(d.elements) and ctx.numbers(K.PID_VELOCITY) and ctx.numbers(K.MOTOR):
        done.append("SET_VELOCITY (see command_timeout)")
    return ", ".join(done) or "no actuator"


async def _wheel_speed(probe: Probe, motor: int, moving: bool, timeout: float) -> float:
    mark = probe.mark()
    frame = await probe.expect(
        mark,
        lambda b: b[0] == p.Op.ENCODER and b[1] == motor and (p.parse_encoder(b)[2] != 0) == moving,
        timeout,
        f"encoder {motor} {'moving' if moving else 'stopped'}",
    )
    return frame.t


@check("command_timeout", "6 (when the master dies)")
async def check_command_timeout(ctx: Context) -> str:
    motors, pids = ctx.numbers(K.MOTOR), ctx.numbers(K.PID_VELOCITY)
    if not motors or not pids:
        return "no PID agent"
    probe, motor, pid = ctx.probe, motors[0], pids[0]
    status = await probe.command(p.set_param(pid, p.Param.COMMAND_TIMEOUT_MS, 300))
    expect_status(status, p.AckStatus.OK, "COMMAND_TIMEOUT_MS 300")
    probe.send(p.set_velocity(pid, 0.2))
    await _wheel_speed(probe, motor, True, 1.0)
    silent_from = time.time()  # the master falls silent
    stopped = await _wheel_speed(probe, motor, False, 2.5)
    waited = stopped - silent_from
    probe.send(p.set_velocity(pid, 0.2))  # and STOP stops it at once
    await _wheel_speed(probe, motor, True, 1.0)
    probe.send(bytes([p.Op.STOP]), can_id=p.BROADCAST_ID)
    await _wheel_speed(probe, motor, False, 1.0)
    await probe.command(
        p.set_param(pid, p.Param.COMMAND_TIMEOUT_MS, p.PARAM_DEFAULTS[p.Param.COMMAND_TIMEOUT_MS])
    )
    return f"stopped {waited * 1000:.0f} ms after it was seen moving (time-out 300 ms); STOP works"


@check("block_to_module", "5.3, 5.4, 5.5")
async def check_blocks(ctx: Context) -> str:
    probe, d = ctx.probe, ctx.d
    junk = bytes([0xFE, 0]) + bytes(range(28))  # CONFIG for a missing element: 5 data frames
    status = await probe.send_block(p.BlockType.CONFIG, junk, drop=2)
    if status != p.EndStatus.REFUSED:
        raise CheckFailed(f"CONFIG for a missing element (frame 2 lost on the way): END {status}")
    status = await probe.send_block(p.BlockType.CONFIG, junk, stall=1)
    if status != p.EndStatus.REFUSED:
        raise CheckFailed(f"CONFIG after a stall: END {status}")
    status = await probe.send_block(0x7E, bytes(10))
    if status != p.EndStatus.UNKNOWN_TYPE:
        raise CheckFailed(f"unknown block type: END {status}, expected UNKNOWN_TYPE")
    done = "gap re-requested, time-out re-requested, bad content REFUSED, UNKNOWN_TYPE"
    for i in ctx.numbers(K.FIRING_SEQUENCE):
        count = sum(c for _, c in d.numbering(K.SONAR).values())
        good = bytes([i, 0, *range(count)])
        status = await probe.send_block(p.BlockType.CONFIG, good)
        if status != p.EndStatus.OK:
            raise CheckFailed(f"a valid firing order for element {i}: END {status}")
        status = await probe.send_block(p.BlockType.CONFIG, bytes([i, 0, count]))
        if status != p.EndStatus.REFUSED:
            raise CheckFailed(f"firing order naming sonar {count} of {count}: END {status}")
        done += f", firing order of element {i}"
    return done


@check("garbage_ignored", "3 (frame layout)")
async def check_garbage(ctx: Context) -> str:
    probe = ctx.probe
    mark = probe.mark()
    for data in (
        bytes([p.Op.QUERY, 0]),  # wrong length
        bytes([0x7F, 1, 2]),  # unknown opcode
        bytes([p.Op.SET_PARAM, 0, 1]),  # truncated
        p.encoder(0, 0, 0.0),  # a slave opcode sent to a slave
        b"",
    ):
        probe.send(data)
    probe.send(bytes([p.Op.QUERY]), extended=True, can_id=probe.module_id + 1)
    answers = await probe.silence(mark)
    answers = [a for a in answers if a[0] not in p.DATA_KINDS]
    if answers:
        raise CheckFailed(f"answered garbage with {[a.hex() for a in answers]}")
    await probe.query()  # and it still works
    return "no answer, still answers QUERY"


@check("broadcast_id", "3 (broadcast ID)")
async def check_broadcast(ctx: Context) -> str:
    probe = ctx.probe
    mark = probe.mark()
    probe.send(bytes([p.Op.QUERY]), can_id=p.BROADCAST_ID)
    probe.send(p.set_param(p.MODULE, p.Param.WATCHDOG_MS, 100), can_id=p.BROADCAST_ID)
    answers = [a for a in await probe.silence(mark) if a[0] not in p.DATA_KINDS]
    if answers:
        raise CheckFailed(f"answered a non-broadcast opcode on 0x001: {[a.hex() for a in answers]}")
    return "QUERY and SET_PARAM on 0x001 ignored"


@check("disable", "4.9")
async def check_disable(ctx: Context) -> str:
    probe = ctx.probe
    await _enable(ctx, False)
    mark = probe.mark()
    frame = await probe.expect(mark, lambda d: d[0] <= 0x0F, 0.5, "a watchdog")
    if frame.data[0] != p.SlaveState.DISABLED:
        raise CheckFailed("watchdog still says ENABLED after ENABLE 0")
    data = [b for b in await probe.silence(probe.mark()) if b[0] in p.DATA_KINDS]
    await asyncio.sleep(0.3)
    data += [f.data for f in probe.since(mark) if f.data[0] in p.DATA_KINDS and f.t > frame.t]
    if data:
        raise CheckFailed(f"data frames while DISABLED: {[b.hex() for b in data[:3]]}")
    return "watchdog DISABLED, no data frames"


@check("reset_visible", "4.7")
async def check_reset(ctx: Context) -> str:
    """An enabled module that goes DISABLED (MASTER_START here, a reboot in the field) says so
    in its very next watchdog: that is how a master tells a reset from a time-out."""
    probe = ctx.probe
    await _enable(ctx, True)
    await probe.expect(probe.mark(), lambda d: d == bytes([1]), 0.5, "an ENABLED watchdog")
    probe.send(bytes([p.Op.MASTER_START]), can_id=p.BROADCAST_ID)
    await asyncio.sleep(0.01)
    frame = await probe.expect(probe.mark(), lambda d: d[0] <= 0x0F, 0.5, "a watchdog")
    if frame.data != bytes([0]):
        raise CheckFailed("the first watchdog after MASTER_START still says ENABLED")
    return "ENABLED -> DISABLED in the next watchdog"


# --- the run --------------------------------------------------------------------------------


async def _master_bring_up(channel: str, module_id: int) -> Result:
    """Our master, with its drivers, brings the module ONLINE (section 4) and drops it."""
    bus = open_bus(channel)
    master = Master(bus, Bus().endpoint("conformance"), name=channel)
    try:
        await master.start()
        deadline = time.monotonic() + 5.0
        while True:
            module = master.modules.get(module_id)
            if module is not None and module.state is ModuleState.ONLINE:
                return Result("master_bring_up", "4", True, f"online as {module.name}")
            if time.monotonic() > deadline:
                state = module.state.value if module else "never seen"
                return Result("master_bring_up", "4", False, f"not online within 5 s ({state})")
            await asyncio.sleep(0.02)
    finally:
        await master.stop()
        bus.shutdown()


async def run_conformance(channel: str, module_id: int) -> list[Result]:
    """Every check in order against the module ``module_id`` on bus ``channel``. A failed
    check does not stop the others (those that need the description fail with it)."""
    if not p.is_module_id(module_id):
        raise ValueError(f"module id 0x{module_id:X} is not an even ID in 0x02..0x7FE")
    results = [await _master_bring_up(channel, module_id)]
    bus = open_bus(channel)
    probe = Probe(bus, module_id)
    reader = BusReader(bus, probe.on_batch, loop=asyncio.get_running_loop(), name="conformance")
    reader.start()
    ctx = Context(probe, channel=channel)
    try:
        for name, section, fn in CHECKS:
            try:
                detail = await fn(ctx)
                results.append(Result(name, section, True, detail))
            except (CheckFailed, can.CanError) as exc:
                results.append(Result(name, section, False, str(exc)))
        probe.send(bytes([p.Op.MASTER_START]), can_id=p.BROADCAST_ID)  # leave it DISABLED
    finally:
        await asyncio.to_thread(reader.stop)
        bus.shutdown()
    return results


def summary(results: list[Result]) -> dict[str, Any]:
    """The closing JSON line: {"checks", "passed", "failed": [names]}."""
    return {
        "checks": len(results),
        "passed": sum(r.passed for r in results),
        "failed": [r.name for r in results if not r.passed],
    }
