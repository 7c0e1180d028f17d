"""The only module that calls ``can.Bus``: turns a configuration string into an open bus.

``virtual:R1`` (the default, in-process), ``socketcan:can0`` (real hardware), or any python-can
interface as ``interface:channel[,key=value...]`` e.g. ``pcan:PCAN_USBBUS1,bitrate=1000000``.
"""

from __future__ import annotations

from typing import Any

import can

__all__ = ["BusOpenError", "BusSpecError", "open_bus", "parse_bus_spec"]


class BusSpecError(ValueError):
    """A bus configuration string that cannot be understood."""


class BusOpenError(OSError):
    """The interface exists but the bus cannot be opened (no device, no permission...)."""


def parse_bus_spec(spec: str) -> tuple[str, str, dict[str, Any]]:
    """Split ``interface:channel,key=value`` into its parts; integers are converted."""
    interface, sep, rest = spec.partition(":")
    if not sep or not interface or not rest:
        raise BusSpecError(f"bus {spec!r}: expected 'interface:channel', e.g. 'virtual:R1'")
    channel, *options = rest.split(",")
    if not channel:
        raise BusSpecError(f"bus {spec!r}: empty channel")
    kwargs: dict[str, Any] = {}
    for option in options:
        key, eq, value = option.partition("=")
        if not eq or not key:
            raise BusSpecError(f"bus {spec!r}: option {option!r} is not key=value")
        kwargs[key] = int(value) if value.isdigit() else value
    return interface, channel, kwargs


def open_bus(spec: str) -> can.BusABC:
    """Open the bus a spec names. Raises BusSpecError (bad string) or BusOpenError."""
    interface, channel, kwargs = parse_bus_spec(spec)
    if interface not in can.VALID_INTERFACES:
        raise BusSpecError(
            f"bus {spec!r}: unknown interface {interface!r}; "
            f"known: {', '.join(sorted(can.VALID_INTERFACES))}"
        )
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except (OSError, can.CanError, ImportError) as exc:
        raise BusOpenError(f"bus {spec!r} cannot be opened: {exc}") from exc
