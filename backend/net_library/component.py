"""The NetPublisher as a server component (backend.app.COMPONENTS), after the RGM whose
library it installs published nets in: ``app.state.net_library``."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.net_library.service import NetPublisher
from backend.net_library.store import NetStore

__all__ = ["net_library"]


@contextlib.asynccontextmanager
async def net_library(app: FastAPI) -> AsyncIterator[None]:
    publisher = NetPublisher(
        app.state.hub.endpoint("net_library"),
        NetStore(app.state.store.sessionmaker),
        app.state.rgm.library,
    )
    async with publisher:
        app.state.net_library = publisher
        try:
            yield
        finally:
            app.state.net_library = None
