"""A net of the editor run against the scripted environment of ``guidebot petri run``: the
editor's simulation (docs/nets.md). The run is done at once on a virtual clock; its steps (each
firing with the marking after it, each message the net would publish, each scripted reply) are
returned for the page to step through, and as the trace ``petri_nets.trace`` replays.
``simulate_stepwise`` lets the user choose each reply instead, one at a time.
"""

from __future__ import annotations

import io
import json
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import click
from pydantic import ValidationError

from guidebot.bus import Bus
from petri_nets.cli import run_net
from petri_nets.clock import VirtualClock
from petri_nets.compiled import CompiledNet
from petri_nets.dispatch import Dispatch, DispatchError
from petri_nets.library import NetLibrary
from petri_nets.netjson import EditorNet, editor_to_pnml
from petri_nets.scripted import DEFAULT_REPLIES, Reply
from petri_nets.trace import TraceWriter

__all__ = ["MAX_SIMULATED_FIRINGS", "SimulationRefused", "simulate", "simulate_stepwise"]

MAX_SIMULATED_FIRINGS = 2000
"""A simulation stops after this many firings (a looping net): outcome "running"."""


class SimulationRefused(ValueError):
    """The net cannot be run (the engine's problems, a missing parameter, a sub-net unknown)."""


def simulate(
    net: EditorNet,
    params: dict[str, Any],
    replies: dict[str, list[Reply]],
    library: Path,
    *,
    max_time: float = 3600.0,
    max_firings: int = MAX_SIMULATED_FIRINGS,
    published: Mapping[str, CompiledNet] | None = None,
) -> dict[str, Any]:
    """Run ``net`` (sub-nets from ``library``, its ``published`` nets in front; the net
    replaces a library net of its name) with the default scripted replies, ``replies``
    replacing them per message type."""
    script = dict(DEFAULT_REPLIES) | replies
    trace = io.StringIO()
    with tempfile.TemporaryDirectory(prefix="guidebot-sim-") as folder:
        path = Path(folder) / f"{net.id}.pnml"
        path.write_bytes(editor_to_pnml(net))
        try:
            result = run_net(
                path,
                params,
                script,
                library_folder=library,
                max_time=max_time,
                max_firings=max_firings,
                trace=trace,
                installed=published,
            )
        except click.ClickException as exc:
            raise SimulationRefused(exc.message) from None
    result["trace"] = [json.loads(line) for line in trace.getvalue().splitlines() if line]
    return result


def simulate_stepwise(
    net: EditorNet,
    params: dict[str, Any],
    chosen: list[Reply],
    library: Path,
    *,
    max_firings: int = MAX_SIMULATED_FIRINGS,
    published: Mapping[str, CompiledNet] | None = None,
) -> dict[str, Any]:
    """Run ``net`` with the replies the user chose, one at a time: nothing answers but
    ``chosen``, in order, each given once the net has done all it can at that moment; a
    choice ``{"wait": true}`` lets time pass to the next timer. The answer says what the
    net waits for next (``waiting_for``: its instances' enabled message transitions, each
    with the fields it matches) and when its next timer is due (``next_timer``)."""
    with tempfile.TemporaryDirectory(prefix="guidebot-sim-") as folder:
        path = Path(folder) / f"{net.id}.pnml"
        path.write_bytes(editor_to_pnml(net))
        nets = NetLibrary(library, watch=False)
        name = nets.add_file(path)
        if published:
            nets.installed = {n: c for n, c in published.items() if n != name}
        problems = nets.problems_of(name)
        if problems:
            raise SimulationRefused("\n".join(map(str, problems)))
    bus = Bus()
    clock = VirtualClock()
    dispatch = Dispatch(
        bus.endpoint("dispatch"), nets, clock, idle_net=None, step_budget=max_firings
    )
    trace = io.StringIO()
    monitor = bus.endpoint("monitor")
    monitor.subscribe("*", TraceWriter(trace), tap=True)
    top = f"{name}#run"
    outcome: list[str] = []
    monitor.subscribe(
        "petri_net_ended",
        lambda m: outcome.append(m.payload["outcome"]) if m.payload["instance_id"] == top else None,
    )
    environment = bus.endpoint("environment")
    dispatch.open()
    try:
        dispatch.start(name, params, instance_id=top)
        clock.run(until=clock.now(), max_callbacks=max_firings)
        for choice in chosen:
            if outcome:
                break
            if choice.get("wait"):
                due = clock.next_time()
                if due is None:
                    break
                clock.run(until=due, max_callbacks=max_firings)
            else:
                try:
                    environment.publish(str(choice["type"]), dict(choice.get("payload") or {}))
                except ValidationError as exc:
                    raise SimulationRefused(
                        f"reply {choice['type']}: {exc.errors()[0]['msg']}"
                    ) from None
            clock.run(until=clock.now(), max_callbacks=max_firings)
        ended = outcome[0] if outcome else None
        waiting = [] if ended else dispatch.awaited()
        due = None if ended else clock.next_time()
    except DispatchError as exc:
        raise SimulationRefused(str(exc)) from None
    finally:
        dispatch.close()
    return {
        "net": name,
        "outcome": ended or "waiting",
        "time": clock.now(),
        "trace": [json.loads(line) for line in trace.getvalue().splitlines() if line],
        "waiting_for": waiting,
        "next_timer": due,
    }
