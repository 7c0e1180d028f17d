"""The site's media files (pictures of points of interest): names in the site file are paths
relative to the site file's folder, like floor plans; nothing outside that folder is served."""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "MEDIA_HEADERS",
    "MEDIA_TYPES",
    "SERVED_TYPES",
    "VIDEO_TYPES",
    "media_file",
    "media_in",
    "video_url",
]

MEDIA_TYPES = {
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".webp": "image/webp",
    ".gif": "image/gif",
}
"""Pictures the pages show (a point's ``media``; other kinds there are listed but not shown)."""
VIDEO_TYPES = {".mp4": "video/mp4", ".webm": "video/webm"}
"""Videos the pages play: a point's sign-language video (``sign_video``)."""
SERVED_TYPES = {**MEDIA_TYPES, **VIDEO_TYPES}
"""What ``/media/`` serves from the site's folder."""

MEDIA_HEADERS = {
    # A picture: nothing in it may run or load anything (an SVG could carry script).
    "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'",
    "X-Content-Type-Options": "nosniff",
    "Cache-Control": "max-age=300",
}


def video_url(name: object) -> str | None:
    """Where a page plays a video of the site from (None: no name, or not a video)."""
    if not isinstance(name, str) or "." not in name:
        return None
    return f"/media/{name}" if name[name.rfind(".") :].lower() in VIDEO_TYPES else None


def media_file(site_file: Path | None, name: str) -> Path | None:
    """The file of media ``name``, or None when there is no site file, the name leaves the
    site's folder, is not a picture or a video, or the file is missing (pages then show a
    placeholder)."""
    return None if site_file is None else media_in(site_file.resolve().parent, name)


def media_in(folder: Path, name: str) -> Path | None:
    """The file of media ``name`` in the site folder ``folder`` (see ``media_file``)."""
    if not name or "\x00" in name:
        return None
    folder = folder.resolve()
    path = (folder / name).resolve()
    if not path.is_relative_to(folder) or path.suffix.lower() not in SERVED_TYPES:
        return None
    return path if path.is_file() else None
