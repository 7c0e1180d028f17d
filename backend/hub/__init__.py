"""JCentral, the server's publish/subscribe hub (docs/protocol.md)."""

from .core import Hub, HubBus, RemoteClient
from .outbox import Outbox, OutboxOverflow

__all__ = ["Hub", "HubBus", "Outbox", "OutboxOverflow", "RemoteClient"]
