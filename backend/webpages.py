"""The web pages (web/): static files served with security headers.

Pages are static HTML and ES modules (docs/architecture.md, "Web pages"). Every HTML page gets a
Content-Security-Policy that allows scripts from this server only: no inline script except the
page's import map, allowed by its SHA-256 hash (computed when the file is served).
"""

from __future__ import annotations

import base64
import hashlib
import os
import re
from functools import lru_cache
from pathlib import Path

from starlette.responses import FileResponse, Response
from starlette.staticfiles import StaticFiles
from starlette.types import Scope

__all__ = ["WebFiles", "csp_for", "page"]

_INLINE_SCRIPT = re.compile(rb"<script\b[^>]*>(.*?)</script>", re.DOTALL | re.IGNORECASE)

BASE_POLICY = (
    "default-src 'self'; img-src 'self' data: blob:; style-src 'self' 'unsafe-inline'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; "
    "frame-ancestors 'none'"
)


@lru_cache(maxsize=256)
def _inline_hashes(path: str, mtime_ns: int) -> tuple[str, ...]:
    with open(path, "rb") as f:
        html = f.read()
    hashes = []
    for body in _INLINE_SCRIPT.findall(html):
        if body.strip():
            digest = base64.b64encode(hashlib.sha256(body).digest()).decode()
            hashes.append(f"'sha256-{digest}'")
    return tuple(hashes)


def csp_for(path: str) -> str:
    """The policy of one HTML file: scripts from 'self' plus its inline blocks by hash."""
    hashes = _inline_hashes(path, os.stat(path).st_mtime_ns)
    return f"{BASE_POLICY}; script-src 'self' {' '.join(hashes)}".rstrip()


def page(path: Path) -> FileResponse:
    """One HTML page of web/ at a path of its own (``/docs``), with the pages' headers."""
    return FileResponse(
        path,
        media_type="text/html",
        headers={
            "Content-Security-Policy": csp_for(str(path)),
            "Cache-Control": "no-cache",
            "X-Content-Type-Options": "nosniff",
            "Referrer-Policy": "no-referrer",
        },
    )


class WebFiles(StaticFiles):
    """StaticFiles with a CSP on HTML pages and nosniff/no-referrer on everything."""

    def file_response(
        self,
        full_path: str | os.PathLike[str],
        stat_result: os.stat_result,
        scope: Scope,
        status_code: int = 200,
    ) -> Response:
        response = super().file_response(full_path, stat_result, scope, status_code)
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        if str(full_path).endswith(".html"):
            response.headers["Content-Security-Policy"] = csp_for(str(full_path))
            response.headers["Cache-Control"] = "no-cache"
        return response
