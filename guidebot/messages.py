"""The one message envelope used everywhere: hub, WebSocket, on-board bus.

Every message carries routing fields (type, source, destination, correlation id) and a free
JSON payload. Payload models live in ``guidebot.payloads`` and are registered by type name so
the hub can refuse unknown types and validate known ones.

Typed once: a message carries its payload model next to the JSON dict, filled where the message
enters (the hub validates a client's payload into its model, ``make_message`` keeps the model a
component published) or, failing that, on the first ``typed()``. Handlers subscribed by model
(``endpoint.on(Model, handler)``, guidebot/bus.py) get that one object; nobody validates twice.
The model is shared by every handler of the message: read it, never change it.
"""

from __future__ import annotations

import builtins
import itertools
import os
import time
from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, Strict

__all__ = [
    "ENVELOPE_VERSION",
    "Message",
    "Payload",
    "PayloadModel",
    "UnknownMessageType",
    "WireEnum",
    "keep_typed",
    "known_types",
    "make_message",
    "new_message_id",
    "payload_model",
    "register_payload",
    "type_name",
    "type_names",
]

ENVELOPE_VERSION = 1

_ID_PREFIX = os.urandom(4).hex()
_ID_COUNTER = itertools.count(1)


def new_message_id() -> str:
    """Unique, cheap and sortable per process: a random process prefix and a counter."""
    return f"{_ID_PREFIX}-{next(_ID_COUNTER):x}"


class Message(BaseModel):
    """The envelope. ``payload`` is plain JSON; its schema is given by ``type``. Strict as the
    payloads are (``"version": true`` is not 1)."""

    __slots__ = ("_typed",)
    """The payload model, once known (``typed``): a slot, not a field or a pydantic private
    attribute, so it costs nothing to build a message, is not encoded, is not compared by
    ``==``, and a copy (``model_copy``) starts without it."""

    model_config = ConfigDict(extra="forbid", strict=True)

    type: str = Field(min_length=1, max_length=64, pattern=r"^[a-z][a-z0-9_.]*$")
    id: str = Field(default_factory=new_message_id, min_length=1, max_length=64)
    timestamp: float = Field(default_factory=time.time)
    source: str = Field(default="", max_length=64)
    destination: str | None = Field(default=None, max_length=64)
    correlation_id: str | None = Field(default=None, max_length=64)
    version: int = ENVELOPE_VERSION
    payload: dict[str, Any] = Field(default_factory=dict)

    def typed(self, model: builtins.type[M]) -> M:
        """The payload as ``model``: the one the message came with, else validated once and
        kept (raises pydantic's ValidationError for a payload that is not a ``model``)."""
        cached = _cached(self)
        if type(cached) is model:
            return cached  # type: ignore[return-value]  # checked by the line above
        value = model.model_validate(self.payload)
        _keep(self, value)
        return value

    payload_as = typed
    """The older name of ``typed``."""

    def typed_or_none(self) -> BaseModel | None:
        """The payload model the message carries, if it is known yet."""
        cached = _cached(self)
        return cached if isinstance(cached, BaseModel) else None

    def keep_typed(self, payload: BaseModel) -> None:
        """Attach the model this message's payload was validated into (the hub, at the edge)."""
        _keep(self, payload)

    def reply(self, type: str | BaseModel, payload: Payload = None, *, source: str = "") -> Message:
        """Build the reply to this message: addressed to its source, correlated by its id."""
        return make_message(
            type, payload, source=source, destination=self.source or None, correlation_id=self.id
        )


_TYPED_SLOT = Message.__dict__["_typed"]
"""The slot's own descriptor: an empty slot raises at once, without pydantic's __getattr__."""

_get_typed = _TYPED_SLOT.__get__

keep_typed: Callable[[Message, BaseModel], None] = _TYPED_SLOT.__set__
"""``keep_typed(message, payload)``: ``message.keep_typed(payload)`` without a Python call (the
hub does it for every message it receives)."""

_keep = keep_typed


def _cached(message: Message) -> object:
    try:
        return _get_typed(message)
    except AttributeError:
        return None


class PayloadModel(BaseModel):
    """Base class for payloads: a closed object of strict values, as the REST bodies are
    (backend/rest/models.py): unknown fields are refused so typos surface at once, and nothing
    is coerced (``true`` is not 1, ``"2"`` not 2, 1 is a number, ``1`` not ``true``).

    JSON says an enum's member by its value: an enum field is annotated ``WireEnum`` (lax for
    that field only), so ``"idle"`` is a ``RobotMode`` and ``1`` is not."""

    model_config = ConfigDict(extra="forbid", strict=True)


WireEnum = Strict(False)
"""``Annotated[SomeStrEnum, WireEnum]``: a strict model's enum field that takes the member's
JSON value (pydantic's strict mode wants the member itself)."""


M = TypeVar("M", bound=BaseModel)

_REGISTRY: dict[str, type[BaseModel]] = {}
_TYPE_NAMES: dict[type[BaseModel], list[str]] = {}


class UnknownMessageType(KeyError):
    """A message type nobody registered."""


def register_payload(type_name: str) -> Any:
    """Class decorator: bind a payload model to a message type name."""

    def decorate(model: type[M]) -> type[M]:
        existing = _REGISTRY.get(type_name)
        if existing is not None and existing is not model:
            raise ValueError(f"message type {type_name!r} is already bound to {existing.__name__}")
        _REGISTRY[type_name] = model
        names = _TYPE_NAMES.setdefault(model, [])
        if type_name not in names:
            names.append(type_name)
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


def type_names(model: builtins.type[BaseModel]) -> tuple[str, ...]:
    """Every message type a payload model is registered for (one, but BatteryAlarm has two)."""
    _load_catalogue()
    names = _TYPE_NAMES.get(model)
    if not names:
        raise TypeError(f"{model.__name__} is not a registered payload model")
    return tuple(names)


def _load_catalogue() -> None:
    # Imported lazily: the catalogue imports this module.
    import guidebot.payloads  # noqa: F401


def type_name(model: builtins.type[BaseModel]) -> str:
    """The message type a payload model is registered for; a model bound to several types
    (BatteryAlarm: battery_low and battery_panic) needs the type name given with it."""
    _load_catalogue()
    names = _TYPE_NAMES.get(model, [])
    if len(names) == 1:
        return names[0]
    if not names:
        raise TypeError(f"{model.__name__} is not a registered payload model")
    raise TypeError(
        f"{model.__name__} is the payload of {', '.join(sorted(names))}: give the type name with it"
    )


Payload = dict[str, Any] | BaseModel | None
"""What a sender publishes: a payload model (preferred: the type name comes with it), or a
plain dict with the type name given."""


def make_message(
    type_or_payload: str | BaseModel,
    payload: Payload = None,
    *,
    source: str = "",
    destination: str | None = None,
    correlation_id: str | None = None,
) -> Message:
    """The envelope for ``publish(RequestArea(...))`` or ``publish("request_area", {...})``.

    A payload model is validated where it is built, so a sender's mistake raises at the
    sender; it travels as its JSON dict, as a dict payload would, and as itself: in-process
    handlers subscribed by model receive that very object (``Message.typed``).
    """
    model: BaseModel | None = None
    if type(type_or_payload) is str and (payload is None or type(payload) is dict):
        # The common case, without pydantic's (ABC) isinstance checks.
        type_, body = type_or_payload, payload
    else:
        type_, body = _typed(type_or_payload, payload)
        model = type_or_payload if payload is None else payload  # type: ignore[assignment]
    message = Message(
        type=type_,
        source=source,
        destination=destination,
        correlation_id=correlation_id,
        payload=body or {},
    )
    if isinstance(model, BaseModel):
        _keep(message, model)
    return message


def _typed(type_or_payload: str | BaseModel, payload: Payload) -> tuple[str, dict[str, Any]]:
    """Type name and JSON dict of a message given with a payload model."""
    if isinstance(type_or_payload, BaseModel):
        if payload is not None:
            raise TypeError("give either a payload model or a type name and a payload")
        payload = type_or_payload
        type_ = type_name(builtins.type(payload))
    else:
        type_ = type_or_payload
    if isinstance(payload, BaseModel):
        _load_catalogue()
        expected = _REGISTRY.get(type_)
        if expected is not None and expected is not builtins.type(payload):
            raise TypeError(
                f"{type_!r} carries {expected.__name__}, not {builtins.type(payload).__name__}"
            )
        return type_, payload.model_dump(mode="json")
    return type_, payload or {}
