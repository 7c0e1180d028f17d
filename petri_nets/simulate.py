"""A net of the editor run against the scripted environment of ``guidebot petri run``: the
editor's simulation (docs/nets.md). The run is done at once on a virtual clock; its steps (each
firing with the marking after it, each message the net would publish, each scripted reply) are
returned for the page to step through, and as the trace ``petri_nets.trace`` replays.
"""

from __future__ import annotations

import io
import json
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import click

from petri_nets.cli import run_net
from petri_nets.compiled import CompiledNet
from petri_nets.netjson import EditorNet, editor_to_pnml
from petri_nets.scripted import DEFAULT_REPLIES, Reply

__all__ = ["MAX_SIMULATED_FIRINGS", "SimulationRefused", "simulate"]

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
