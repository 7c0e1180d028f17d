"""``guidebot plan --html REPORT``: the plan as one self-contained page (docs/planning.md,
"The report page"): the answer, the wait against fleet size drawn with the vendored uPlot
(inlined, so the file opens anywhere without a network), the rows, and for a live run a heat map
of the time lost waiting for each restricted area and elevator per fleet size."""

from __future__ import annotations

import base64
import json
from html import escape
from pathlib import Path
from typing import Any

from guidebot.paths import WEB_DIR

__all__ = ["render_report", "write_report"]

VENDOR = WEB_DIR / "vendor" / "uplot"
COLUMNS = (
    ("mode", "Run"),
    ("policy", "Policy"),
    ("robots", "Robots"),
    ("served", "Served"),
    ("refused", "Refused"),
    ("abandoned", "Gave up"),
    ("wait_p50_s", "Wait p50"),
    ("wait_p95_s", "Wait p95"),
    ("served_within_share", "Within"),
    ("tours_per_hour", "Tours / h"),
    ("utilisation", "Busy"),
    ("lock_wait_s", "Lock waits"),
    ("elevator_wait_s", "Elevator waits"),
    ("charging_s", "Charging"),
)


def write_report(result: dict[str, Any], path: Path) -> None:
    path.write_text(render_report(result), encoding="utf-8")


def _minutes(seconds: Any) -> str:
    return "&ndash;" if seconds is None else f"{seconds / 60:.1f} min"


def _cell(key: str, value: Any) -> str:
    if value is None:
        return "&ndash;"
    if key in ("wait_p50_s", "wait_p95_s", "lock_wait_s", "elevator_wait_s", "charging_s"):
        return _minutes(value)
    if key in ("served_within_share", "utilisation"):
        return f"{value:.0%}"
    return escape(str(value))


def _answer(rows: list[dict[str, Any]], within: float) -> str:
    """The smallest fleet, per run and policy, that serves 95 % of the requests within the
    report's minutes."""
    lines = []
    for mode, policy in dict.fromkeys((r["mode"], r["policy"]) for r in rows):
        fits = [
            r["robots"]
            for r in rows
            if (r["mode"], r["policy"]) == (mode, policy)
            and (r["served_within_share"] or 0) >= 0.95
        ]
        what = f"{escape(mode)} ({escape(policy)})"
        if fits:
            lines.append(
                f"<li>{what}: <strong>{_robots(min(fits))}</strong> "
                f"{'serve' if min(fits) > 1 else 'serves'} 95 % of the requests within "
                f"{within:g} min.</li>"
            )
        else:
            lines.append(f"<li>{what}: no fleet tried serves 95 % within {within:g} min.</li>")
    return "<ul>" + "".join(lines) + "</ul>"


def _robots(n: int) -> str:
    return f"{n} robot{'s' if n != 1 else ''}"


def _heat(rows: list[dict[str, Any]], key: str, title: str) -> str:
    """Places (rows) by fleet size (columns), each cell the minutes lost waiting there, its
    background darker the longer."""
    live = [r for r in rows if r["mode"] in ("live", "virtual")]
    places = sorted({p for r in live for p in (r.get(key) or {})})
    if not live:
        return ""
    if not places:
        return f"<h3>{escape(title)}</h3><p>No wait in the live runs.</p>"
    most = max((r[key][p]["total_s"] for r in live for p in r[key]), default=0.0) or 1.0
    head = "".join(f'<th scope="col">{_robots(r["robots"])}</th>' for r in live)
    body = []
    for place in places:
        cells = []
        for r in live:
            seen = (r.get(key) or {}).get(place)
            if seen is None:
                cells.append('<td class="heat" style="--heat: 0">&ndash;</td>')
                continue
            share = seen["total_s"] / most
            cells.append(
                f'<td class="heat" style="--heat: {share:.3f}">{_minutes(seen["total_s"])}'
                f' <span class="n">({seen["count"]}&times;)</span></td>'
            )
        body.append(f'<tr><th scope="row">{escape(place)}</th>{"".join(cells)}</tr>')
    return (
        f"<h3>{escape(title)}</h3>"
        f'<table class="heatmap"><thead><tr><th scope="col">Where</th>{head}</tr></thead>'
        f"<tbody>{''.join(body)}</tbody></table>"
    )


def _hours(h: float) -> str:
    return f"{h:g} hour{'s' if h != 1 else ''}"


def _source(result: dict[str, Any]) -> str:
    src = result.get("source") or {}
    if "profile" in src:
        return f"profile “{escape(str(src['profile']))}”"
    if "replay" in src:
        return f"replay file {escape(Path(str(src['replay'])).name)}"
    return f"recorded day {escape(str(src.get('date')))} ({escape(str(src.get('tz')))})"


def render_report(result: dict[str, Any]) -> str:
    """The page's HTML (UTF-8 text)."""
    rows: list[dict[str, Any]] = result["fleets"]
    within = rows[0]["within_min"] if rows else 10.0
    module = (VENDOR / "uPlot.esm.js").read_bytes()
    css = (VENDOR / "uPlot.min.css").read_text(encoding="utf-8")
    head = "".join(f'<th scope="col">{label}</th>' for _, label in COLUMNS)
    body = "".join(
        "<tr>" + "".join(f"<td>{_cell(k, r.get(k))}</td>" for k, _ in COLUMNS) + "</tr>"
        for r in rows
    )
    live = any(r["mode"] in ("live", "virtual") for r in rows)
    scale = next((r.get("time_scale") for r in rows if r["mode"] == "live"), None)
    note = (
        f"Live runs: the real server, Task Manager and Traffic Manager with simulated robots and "
        f"building at {scale:g}\u00d7 the wall clock."
        if live
        else "Model only: add --live to play the day on the real server (lock and elevator "
        "waits, doors, charging)."
    )
    waiting = (
        _heat(rows, "lock_wait", "Waits for a restricted area")
        + _heat(rows, "elevator_wait", "Waits for an elevator")
        if live
        else "<p>Run with --live to measure it.</p>"
    )
    data = json.dumps(result).replace("</", "<\\/")
    uplot = base64.b64encode(module).decode()
    return f"""<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>GuideBot plan: {escape(str(result.get("site")))}</title>
<style>{css}</style>
<style>
body {{ font: 15px/1.45 system-ui, sans-serif; color: #1f1f1f; margin: 1.5rem auto;
  max-width: 68rem; padding: 0 1rem; }}
h1 {{ font-size: 1.5rem; }} h2 {{ font-size: 1.2rem; margin-top: 2rem; }} h3 {{ font-size: 1rem; }}
table {{ border-collapse: collapse; margin: .5rem 0 1rem; }}
th, td {{ border: 1px solid #c4c7c5; padding: .25rem .5rem; text-align: right;
  white-space: nowrap; }}
th[scope=row], td:first-child {{ text-align: left; }}
thead th {{ background: #eef1f6; }}
td.heat {{ background: rgb(255 calc(255 - 110 * var(--heat)) calc(255 - 170 * var(--heat))); }}
td.heat .n {{ color: inherit; }}
.n {{ color: #444; font-size: .85em; }}
figure {{ margin: 0; }} figcaption {{ font-size: .9rem; color: #444; }}
.legend-note {{ color: #444; }}
</style>
</head>
<body>
<main>
<h1>How many robots for {escape(str(result.get("site")))}?</h1>
<p>{result.get("requests")} tour requests over {_hours(result.get("day_h", 0))} from the
{_source(result)}. {escape(note)}</p>
<h2>The answer</h2>
{_answer(rows, within)}
<h2>Wait against fleet size</h2>
<figure>
<div id="waits" role="img"
  aria-label="Wait p50 and p95 in minutes against the number of robots"></div>
<figcaption>The visitors' wait from the request to the robot at the tour's first point, in
minutes (p50 and p95), for each fleet size tried.</figcaption>
</figure>
<h2>Every run</h2>
<table id="rows"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>
<h2>Time lost waiting (live runs)</h2>
{waiting}
</main>
<script type="application/json" id="plan-data">{data}</script>
<script type="module">
import uPlot from "data:text/javascript;base64,{uplot}";
const result = JSON.parse(document.getElementById("plan-data").textContent);
const sizes = [...new Set(result.fleets.map((r) => r.robots))].sort((a, b) => a - b);
const runs = [...new Set(result.fleets.map((r) => `${{r.mode}} ${{r.policy}}`))];
const colours = ["#0b57d0", "#b3261e", "#1b7a3a", "#8a4b00", "#6b3fa0", "#00639b"];
const series = [{{ label: "robots" }}];
const data = [sizes];
runs.forEach((run, i) => {{
  const lines = [["wait_p50_s", "p50", undefined], ["wait_p95_s", "p95", [6, 4]]];
  for (const [key, name, dash] of lines) {{
    series.push({{ label: `${{run}} ${{name}}`, stroke: colours[i % colours.length], width: 2, dash,
      points: {{ show: true }},
      value: (u, v) => (v == null ? "\u2013" : `${{v.toFixed(1)}} min`) }});
    data.push(sizes.map((n) => {{
      const row = result.fleets.find((r) => `${{r.mode}} ${{r.policy}}` === run && r.robots === n);
      return row && row[key] != null ? row[key] / 60 : null;
    }}));
  }}
}});
const chart = new uPlot({{
  width: Math.min(900, document.querySelector("main").clientWidth), height: 320, series,
  scales: {{ x: {{ time: false }} }},
  axes: [{{ label: "robots", incrs: [1] }}, {{ label: "wait (min)" }}],
}}, data, document.getElementById("waits"));
document.body.dataset.drawn = String(chart.series.length - 1);
</script>
</body>
</html>
"""
