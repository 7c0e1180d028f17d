"""Record and replay firing traces: JSON lines of petri_net_event (and any other message).

A trace is what a monitor saw on the bus, one message per line. Replaying it rebuilds every
instance's marking at any point (``until``), which is how a GUI scrubs through a recorded run.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from guidebot.messages import Message

__all__ = ["TraceWriter", "read_trace", "replay"]


class TraceWriter:
    """A bus handler that appends each message as one JSON line."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.count = 0

    def __call__(self, message: Message) -> None:
        self.stream.write(message.model_dump_json() + "\n")
        self.count += 1


def read_trace(path: str | Path) -> Iterator[dict[str, Any]]:
    """The messages of a trace file (as dicts), in order."""
    with Path(path).open(encoding="utf-8") as stream:
        for number, line in enumerate(stream, 1):
            if line.strip():
                try:
                    yield json.loads(line)
                except json.JSONDecodeError as exc:
                    raise ValueError(f"{path}:{number}: not JSON ({exc.msg})") from None


def replay(
    messages: Iterable[dict[str, Any]], *, until: float | None = None
) -> dict[str, dict[str, int]]:
    """Marking of every instance after the events up to time ``until`` (all when None)."""
    markings: dict[str, dict[str, int]] = {}
    for message in messages:
        if message.get("type") != "petri_net_event":
            continue
        event = message["payload"]
        if until is not None and event["time"] > until:
            break
        if event["kind"] in ("started", "ended"):
            markings[event["instance_id"]] = dict(event["marking"])
        else:
            markings.setdefault(event["instance_id"], {}).update(event["marking"])
    return {
        instance: {place: n for place, n in marking.items() if n}
        for instance, marking in markings.items()
    }
