"""The JSON form of messages on the WebSocket, written once for the hub and its clients.

A frame carries one message as a JSON object, or several as a JSON array (docs/protocol.md).
"""

from __future__ import annotations

import orjson
from pydantic_core import to_jsonable_python

from guidebot.messages import Message

__all__ = ["encode", "frame"]


def encode(message: Message) -> bytes:
    """JSON bytes of a message (orjson over the model's fields: several times faster than
    ``model_dump_json``; payload values pydantic knows are converted by ``to_jsonable_python``)."""
    return orjson.dumps(message.__dict__, default=to_jsonable_python)


def frame(batch: list[bytes]) -> bytes:
    """One WebSocket frame for encoded messages: the object itself, or an array of them."""
    if len(batch) == 1:
        return batch[0]
    return b"[" + b",".join(batch) + b"]"
