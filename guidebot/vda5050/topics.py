"""Topic names (``interfaceName/majorVersion/manufacturer/serialNumber/topic``) and the
broker's address (``mqtt://user:password@host:port``)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from datetime import UTC, datetime
from urllib.parse import unquote, urlsplit

__all__ = ["BrokerAddress", "Vehicle", "parse_broker", "timestamp"]


@dataclass(frozen=True)
class Vehicle:
    """One vehicle's names on the broker."""

    manufacturer: str
    serial_number: str
    interface: str = "uagv"
    version: str = "2.1.0"

    @property
    def major(self) -> str:
        return "v" + self.version.split(".")[0]

    def topic(self, name: str) -> str:
        return f"{self.interface}/{self.major}/{self.manufacturer}/{self.serial_number}/{name}"

    def header(self, header_id: int) -> dict[str, object]:
        """The fields every message starts with."""
        return {
            "headerId": header_id,
            "timestamp": timestamp(),
            "version": self.version,
            "manufacturer": self.manufacturer,
            "serialNumber": self.serial_number,
        }


def timestamp(at: float | None = None) -> str:
    """ISO 8601 UTC with milliseconds, as the spec writes it (2017-04-15T11:40:03.123Z)."""
    moment = datetime.fromtimestamp(time.time() if at is None else at, UTC)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 1000:03d}Z"


@dataclass(frozen=True)
class BrokerAddress:
    host: str
    port: int
    tls: bool = False
    username: str | None = None
    password: str | None = None

    def __str__(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"


def parse_broker(url: str) -> BrokerAddress:
    """``mqtt://[user[:password]@]host[:1883]`` or ``mqtts://...[:8883]`` (TLS); raises
    ValueError saying what is wrong."""
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts"):
        raise ValueError(f"broker address {url!r}: expected mqtt://host:port or mqtts://host:port")
    if not parts.hostname:
        raise ValueError(f"broker address {url!r}: no host")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"broker address {url!r}: bad port") from None
    tls = parts.scheme == "mqtts"
    return BrokerAddress(
        host=parts.hostname,
        port=port if port is not None else (8883 if tls else 1883),
        tls=tls,
        username=unquote(parts.username) if parts.username else None,
        password=unquote(parts.password) if parts.password else None,
    )
