"""The one message envelope used everywhere: hub, WebSocket, on-board bus.

Every message carries routing fields (type, source, destination, correlation id) and a free
JSON payload. Payload models live in ``guidebot.payloads`` and are registered by type name so
the hub can refuse unknown types and validate known ones.
"""

from __future__ import annotations

import builtins
import itertools
import os
import time
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field

__all__ = [
    "ENVELOPE_VERSION",
    "Message",
    "PayloadModel",
    "UnknownMessageType",
    "known_types",
    "new_message_id",
    "payload_model",
    "register_payload",
]

ENVELOPE_VERSION = 1

_ID_PREFIX = os.urandom(4).hex()
_ID_COUNTER = itertools.count(1)


def new_message_id() -> str:
    """Unique, cheap and sortable per process: a random process prefix and a counter."""
    return f"{_ID_PREFIX}-{next(_ID_COUNTER):x}"


class Message(BaseModel):
    """The envelope. ``payload`` is plain JSON; its schema is given by ``type``."""

    model_config = ConfigDict(extra="forbid")

    type: str = Field(min_length=1, max_length=64, pattern=r"^[a-z][a-z0-9_.]*$")
    id: str = Field(default_factory=new_message_id, min_length=1, max_length=64)
    timestamp: float = Field(default_factory=time.time)
    source: str = Field(default="", max_length=64)
    destination: str | None = Field(default=None, max_length=64)
    correlation_id: str | None = Field(default=None, max_length=64)
    version: int = ENVELOPE_VERSION
    payload: dict[str, Any] = Field(default_factory=dict)

    def payload_as(self, model: builtins.type[M]) -> M:
        """Validate the payload against a payload model."""
        return model.model_validate(self.payload)

    def reply(
        self, type: str, payload: dict[str, Any] | None = None, *, source: str = ""
    ) -> Message:
        """Build the reply to this message: addressed to its source, correlated by its id."""
        return Message(
            type=type,
            source=source,
            destination=self.source or None,
            correlation_id=self.id,
            payload=payload or {},
        )


class PayloadModel(BaseModel):
    """Base class for payloads: unknown fields are refused so typos surface at once."""

    model_config = ConfigDict(extra="forbid")


M = TypeVar("M", bound=BaseModel)

_REGISTRY: dict[str, type[BaseModel]] = {}


class UnknownMessageType(KeyError):
    """A message type nobody registered."""


def register_payload(type_name: str) -> Any:
    """Class decorator: bind a payload model to a message type name."""

    def decorate(model: type[M]) -> type[M]:
        existing = _REGISTRY.get(type_name)
        if existing is not None and existing is not model:
            raise ValueError(f"message type {type_name!r} is already bound to {existing.__name__}")
        _REGISTRY[type_name] = model
        return model

    return decorate


def payload_model(type_name: str) -> type[BaseModel]:
    """The payload model of a type; raises UnknownMessageType."""
    _load_catalogue()
    try:
        return _REGISTRY[type_name]
    except KeyError:
        raise UnknownMessageType(type_name) from None


def known_types() -> frozenset[str]:
    _load_catalogue()
    return frozenset(_REGISTRY)


def _load_catalogue() -> None:
    # Imported lazily: the catalogue imports this module.
    import guidebot.payloads  # noqa: F401
