"""``guidebot petri``: check nets, run one against a scripted environment, export as PNML."""

from __future__ import annotations

import contextlib
import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

import click

from guidebot.bus import Bus
from guidebot.messages import Message
from petri_nets.clock import VirtualClock
from petri_nets.compiled import CompiledNet
from petri_nets.dispatch import Dispatch, DispatchError
from petri_nets.engine import STEP_BUDGET
from petri_nets.library import DEFAULT_LIBRARY, NetLibrary
from petri_nets.model import Problem
from petri_nets.pnml import read_pnml_file, write_pnml
from petri_nets.scripted import DEFAULT_REPLIES, ScriptedEnvironment, parse_reply_option
from petri_nets.templates import parse_literal
from petri_nets.trace import TraceWriter
from petri_nets.validate import validate

__all__ = ["check_files", "petri", "run_net"]

MAX_CALLBACKS = 1_000_000
"""Clock callbacks a dry run may take: a net that spins without letting time pass stops here."""
MAX_FIRINGS = 10_000
"""Default firing guard of a dry run: a net still firing after this many is reported running."""
MAX_LISTED = 1000
"""Firings listed in the result (``firings`` counts them all)."""


@click.group()
def petri() -> None:
    """RoboGraph Petri nets: check, run, export."""


def check_files(paths: list[Path]) -> list[Problem]:
    """Every problem of the files, including references to sub-nets missing from their folder."""
    problems: list[Problem] = []
    for path in paths:
        doc, found = read_pnml_file(path)
        if doc is not None:
            found += validate(doc)
        problems += found
        if doc is not None and not found and path.suffix == ".pnml":
            library = NetLibrary(path.parent, watch=False)
            resolved = str(path.parent / path.name)
            problems += [p for p in library.problems() if p.file == resolved]
    return problems


@petri.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
def check(files: tuple[Path, ...]) -> None:
    """Validate FILES; print file:line: message per problem; exit 1 on any."""
    problems = check_files(list(files))
    for problem in problems:
        click.echo(str(problem))
    if problems:
        click.echo(f"{len(problems)} problem(s)", err=True)
        sys.exit(1)
    click.echo(f"{len(files)} file(s) OK", err=True)


def run_net(
    path: Path,
    params: dict[str, Any],
    replies: dict[str, list[dict[str, Any]]],
    *,
    library_folder: Path | None = None,
    max_time: float = 3600.0,
    max_firings: int = MAX_FIRINGS,
    echo: Any = None,
    trace: IO[str] | None = None,
    installed: Mapping[str, CompiledNet] | None = None,
) -> dict[str, Any]:
    """Run one net on a virtual clock against scripted replies; the result of ``petri run``.
    ``installed``: nets published from the editor, in front of the folder's (the net run
    itself excepted).

    It stops at ``max_time`` virtual seconds or after ``max_firings`` firings of the net and
    its sub-nets (a plain net may loop forever without letting time pass): outcome "running".
    """
    library = NetLibrary(library_folder or path.parent, watch=False)
    name = library.add_file(path)
    if installed:
        library.installed = {n: net for n, net in installed.items() if n != name}
    problems = library.problems_of(name)
    if problems:
        raise click.ClickException("\n".join(map(str, problems)))
    bus = Bus()
    clock = VirtualClock()
    environment = ScriptedEnvironment(bus, clock, replies)
    # steps no longer than the guard, so a looping net stops at it exactly
    dispatch = Dispatch(
        bus.endpoint("dispatch"),
        library,
        clock,
        idle_net=None,
        step_budget=max(1, min(max_firings, STEP_BUDGET)),
    )
    firings = [0]
    fired: list[str] = []
    published: list[str] = []
    marking: dict[str, int] = {}
    top: dict[str, Any] = {"id": None, "outcome": None, "firings": 0}

    def watch(message: Message) -> None:
        payload = message.payload
        if message.type == "petri_net_event":
            steps = payload.get("transitions") or []
            firings[0] += len(steps)
            if echo is not None:
                for transition in steps:
                    echo(f"{clock.now():10.3f} s  {payload['instance_id']:<24} fired {transition}")
            if payload["instance_id"] == top["id"] or top["id"] is None:
                if payload["kind"] in ("started", "ended"):
                    marking.clear()
                fired.extend(steps[: MAX_LISTED - len(fired)])
                top["firings"] += len(steps)
                marking.update(payload["marking"])
        elif message.type == "petri_net_ended":
            if payload["instance_id"] == top["id"]:
                top["outcome"] = payload["outcome"]
        elif message.source == "dispatch":
            published.append(message.type)
            if echo is not None:
                echo(
                    f"{clock.now():10.3f} s  publish {message.type} "
                    f"{json.dumps(message.payload, sort_keys=True)}"
                )

    monitor = bus.endpoint("monitor")
    monitor.subscribe("*", watch, tap=True)
    if trace is not None:
        monitor.subscribe("*", TraceWriter(trace), tap=True)
    dispatch.open()
    try:
        top["id"] = f"{name}#run"
        dispatch.start(name, params, instance_id=top["id"])
        clock.run(
            until=max_time,
            stop=lambda: top["outcome"] is not None or firings[0] >= max_firings,
            max_callbacks=MAX_CALLBACKS,
        )
        outcome = top["outcome"] or ("running" if clock.next_time() is not None else "stuck")
        final = {k: v for k, v in marking.items() if v}
    except DispatchError as exc:
        raise click.ClickException(str(exc)) from None
    finally:
        dispatch.close()
        environment.close()
        monitor.close()
    return {
        "net": name,
        "outcome": outcome,
        "fired": fired,
        "firings": top["firings"],
        "published": published,
        "final_marking": final,
    }


@petri.command(name="run")
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--param",
    "params",
    multiple=True,
    metavar="K=V",
    help="A net parameter; V is JSON when it parses as JSON, else text.",
)
@click.option(
    "--reply",
    "replies",
    multiple=True,
    metavar="TYPE=JSON",
    help='Answer TYPE with {"type":..,"payload":..,"delay":s} or a list; [] = silence.',
)
@click.option("--no-default-replies", is_flag=True, help="Answer only what --reply says.")
@click.option(
    "--library",
    "library_folder",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder of sub-nets (default: the file's folder).",
)
@click.option("--max-time", default=3600.0, show_default=True, help="Virtual seconds to run.")
@click.option(
    "--max-firings",
    default=MAX_FIRINGS,
    show_default=True,
    type=click.IntRange(min=1),
    help="Stop after this many firings (a looping net): outcome running.",
)
@click.option(
    "--trace",
    "trace_file",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Record every message as JSON lines (replay with petri_nets.trace).",
)
@click.option("--json", "as_json", is_flag=True, help="End with one JSON line (the result).")
def run_command(
    file: Path,
    params: tuple[str, ...],
    replies: tuple[str, ...],
    no_default_replies: bool,
    library_folder: Path | None,
    max_time: float,
    max_firings: int,
    trace_file: Path | None,
    as_json: bool,
) -> None:
    """Run FILE against a scripted environment on a virtual clock; print the firing trace."""
    values: dict[str, Any] = {}
    for item in params:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise click.BadParameter(f"{item!r}: expected K=V", param_hint="--param")
        values[key] = parse_literal(raw)
    script = {} if no_default_replies else dict(DEFAULT_REPLIES)
    for item in replies:
        try:
            message_type, answer = parse_reply_option(item)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--reply") from None
        script[message_type] = answer
    folder = library_folder
    if folder is None and not any(file.parent.glob("*.pnml")):
        folder = DEFAULT_LIBRARY
    with contextlib.ExitStack() as stack:
        trace = stack.enter_context(trace_file.open("w")) if trace_file else None
        result = run_net(
            file,
            values,
            script,
            library_folder=folder,
            max_time=max_time,
            max_firings=max_firings,
            echo=click.echo,
            trace=trace,
        )
    if as_json:
        click.echo(json.dumps(result))
    else:
        click.echo(f"{result['net']}: {result['outcome']}; final marking {result['final_marking']}")


@petri.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write here instead of standard output.",
)
def export(file: Path, output: Path | None) -> None:
    """Write FILE back as standard PNML (what other Petri-net tools read)."""
    doc, problems = read_pnml_file(file)
    if doc is None:
        for problem in problems:
            click.echo(str(problem), err=True)
        sys.exit(1)
    for problem in problems + validate(doc):
        click.echo(f"warning: {problem}", err=True)
    data = write_pnml(doc)
    if output is None:
        click.echo(data.decode("utf-8"), nl=False)
    else:
        output.write_bytes(data)
