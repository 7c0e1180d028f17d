"""What one ``guidebot demo`` run serves: the site file with this run's simulator ports and the
files it names.

Every demo starts from the site file as given (the shipped demo museum by default) on a
database of its own: the building simulator's Modbus modules take free ports at each run, so a
site kept from an earlier run would point at ports where nothing listens (docs/robot.md).
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import yaml

__all__ = ["mismatched_modules", "site_files", "site_with_ports"]


def site_files(data: dict[str, Any]) -> set[str]:
    """The relative paths a site document names: floor plans and media of points of interest
    (their translations' too)."""
    names: set[str] = set()
    for floor in data.get("floors") or []:
        if isinstance(floor, dict) and isinstance(floor.get("plan_image"), str):
            names.add(floor["plan_image"])
    for poi in data.get("pois") or []:
        if not isinstance(poi, dict):
            continue
        texts = [poi, *((poi.get("translations") or {}).values())]
        for text in texts:
            if isinstance(text, dict):
                names.update(m for m in text.get("media") or [] if isinstance(m, str))
    return names


def site_with_ports(site: Path, ports: dict[str, int], folder: Path) -> Path:
    """A copy of ``site`` in ``folder`` whose modules are where the simulator listens, with the
    plans and pictures it names beside it (paths stay relative to the copy's folder)."""
    data = yaml.safe_load(site.read_text(encoding="utf-8"))
    for module in data.get("modules") or []:
        module["port"] = ports.get(module["id"], module.get("port"))
    source = site.resolve().parent
    for name in sorted(site_files(data)):
        origin = (source / name).resolve()
        if not origin.is_relative_to(source) or not origin.is_file():
            continue  # the server refuses it anyway; pages show a placeholder
        target = folder / origin.relative_to(source)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(origin, target)
    path = folder / site.name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def mismatched_modules(site: dict[str, Any], ports: dict[str, int]) -> list[str]:
    """Modules of the server's live site that are not where this run's simulator listens."""
    wrong = []
    for module in site.get("modules") or []:
        if ports.get(module.get("id")) != module.get("port"):
            wrong.append(f"{module.get('id')} (port {module.get('port')})")
    return wrong
