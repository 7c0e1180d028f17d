"""Where a checkout keeps what every process serves or reads: the web pages and the shipped sites.

Neutral ground: the server (backend.settings) and the robot's touch screen (robot_agent.gui)
both serve ``web/``, and neither may import the other.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["ROOT", "SITES_DIR", "WEB_DIR"]

ROOT = Path(__file__).resolve().parent.parent
WEB_DIR = ROOT / "web"
SITES_DIR = ROOT / "sites"
