// Reports: how the robots served visitors over a day, a week or any range (docs/reports.md).
// Figures from GET /api/reports, charts drawn with the vendored uPlot, every table as CSV, and a
// one-page daily summary for the printer (web/admin/reports.css, @media print).
import { html, render, svg } from "lit-html";
import uPlot from "uplot";
import { doorName, floorName, placeName, tourName } from "/admin/names.js";
import { FloorMap } from "/lib/map.js";
import { dateTime, venueDay, venueZone } from "/admin/venue.js";

const STATES = [
  ["touring", "Touring", "#0b57d0"],
  ["errand", "Errands", "#6b3fa0"],
  ["charging", "Charging", "#1b7a3a"],
  ["idle", "Idle", "#9aa0a6"],
  ["faulted", "Faulted", "#b00020"],
  ["offline", "Offline", "#e2e4e8"],
  ["down", "Server down", "#5f6368"],
];
const TASK_SERIES = [
  ["requested", "Requested", "#0b57d0"],
  ["done", "Done", "#1b7a3a"],
  ["failed", "Failed", "#b00020"],
  ["cancelled", "Cancelled", "#8a4b00"],
];
const HOUR_S = 3600;
const DAY_S = 86400;
/** The charts' time axis on the 24-hour clock, day before month ("14:00", "3 Jul"), as every
 * time on the console; uPlot's own is 12-hour and month first ("2pm", "7/3"). uPlot's table:
 * [tick step at least (s), tick label, label when the year, month, day, hour, minute, second
 * rolls over, 1: the roll-over label is added to the tick's]. */
const TIME_AXIS = [
  [DAY_S * 365, "{YYYY}", null, null, null, null, null, null, 1],
  [DAY_S * 28, "{MMM}", "\n{YYYY}", null, null, null, null, null, 1],
  [DAY_S, "{D} {MMM}", "\n{YYYY}", null, null, null, null, null, 1],
  [HOUR_S, "{HH}:{mm}", "\n{D} {MMM} {YYYY}", null, "\n{D} {MMM}", null, null, null, 1],
  [60, "{HH}:{mm}", "\n{D} {MMM} {YYYY}", null, "\n{D} {MMM}", null, null, null, 1],
];
/** The time axis's labels as drawn, on the chart's element (``data-x-ticks``, " | " between
 * them): the canvas holds no text a test or a screen reader could read. */
const tickHook = { draw: [(u) => { u.root.parentElement.dataset.xTicks = (u.axes[0]._values ?? []).join(" | "); }] };
const INCIDENT_NAMES = {
  faults: "Robot faults",
  door_blocks: "Doors that did not open",
  elevator_wait: "Elevator waits",
  lock_wait: "Waits for a restricted area",
  alarms: "Alerts and alarms",
};

const isoDay = (date) => {
  const local = new Date(date.getTime() - date.getTimezoneOffset() * 60000);
  return local.toISOString().slice(0, 10);
};
const monday = (date) => {
  const d = new Date(date);
  d.setDate(d.getDate() - ((d.getDay() + 6) % 7));
  return d;
};

function state(ui) {
  if (!ui.reports) {
    const today = venueDay(); // the venue's day, wherever the browser is
    ui.reports = { mode: "day", day: today, week: isoDay(monday(new Date(`${today}T12:00`))), start: `${today}T08:00`, end: `${today}T20:00`, data: null, error: null, loading: false };
  }
  return ui.reports;
}

/** The query of the chosen period, in the venue's time zone (as every time on the console). */
function query(r) {
  const q = new URLSearchParams({ tz: venueZone() });
  if (r.mode === "day") q.set("day", r.day);
  else if (r.mode === "week") q.set("week", r.week);
  else {
    q.set("start", r.start);
    q.set("end", r.end);
  }
  return q.toString();
}

/** Fetch the chosen period's report; only the last one asked for is shown (an earlier answer
 * arriving later must not replace it). */
async function load(ui) {
  const r = state(ui);
  const asked = (r.asked = (r.asked ?? 0) + 1);
  r.loading = true;
  r.error = null;
  ui.draw();
  let data = null;
  let error = null;
  try {
    data = await ui.api.get(`/api/reports?${query(r)}`);
  } catch (err) {
    error = err.message;
  }
  if (asked !== r.asked) return;
  r.data = data;
  r.error = error;
  r.loading = false;
  ui.draw();
}

async function downloadCsv(ui, figure) {
  const r = state(ui);
  await ui.act(`Download ${figure} as CSV`, async () => {
    const blob = await ui.api.get(`/api/reports/${figure}?${query(r)}&format=csv`);
    const url = URL.createObjectURL(blob);
    const link = document.createElement("a");
    link.href = url;
    link.download = `guidebot-${figure}-${r.data?.period?.start?.slice(0, 10) ?? "report"}.csv`;
    document.body.append(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(url), 1000);
  });
}

const seconds = (s) => {
  if (s === null || s === undefined) return "–";
  if (s < 90) return `${Math.round(s)} s`;
  if (s < 5400) return `${Math.round(s / 60)} min`;
  return `${(s / 3600).toFixed(1)} h`;
};
const share = (x) => (x === null || x === undefined ? "–" : `${Math.round(x * 100)} %`);
const hours = (s) => (s / 3600).toFixed(1);

function csvButton(ui, figure, label) {
  return html`<button type="button" class="secondary no-print" @click=${() => downloadCsv(ui, figure)}>CSV: ${label}</button>`;
}

function form(ui, r) {
  const set = (key) => (e) => { r[key] = e.target.value; ui.draw(); };
  return html`<form class="inline no-print" aria-label="Report period" @submit=${(e) => { e.preventDefault(); load(ui); }}>
      <span class="field"><label for="report-mode">Period</label> <select id="report-mode" name="mode" @change=${set("mode")}>
        <option value="day" ?selected=${r.mode === "day"}>A day</option>
        <option value="week" ?selected=${r.mode === "week"}>A week</option>
        <option value="range" ?selected=${r.mode === "range"}>A custom range</option></select></span>
      ${r.mode === "day" ? html`<label>Day <input type="date" name="day" .value=${r.day} @change=${set("day")} required></label>` : ""}
      ${r.mode === "week" ? html`<label>Week from <input type="date" name="week" .value=${r.week} @change=${set("week")} required></label>` : ""}
      ${r.mode === "range"
        ? html`<label>From <input type="datetime-local" name="start" .value=${r.start} @change=${set("start")} required></label>
            <label>Until <input type="datetime-local" name="end" .value=${r.end} @change=${set("end")} required></label>`
        : ""}
      <button type="submit">Show report</button>
      <button type="button" class="secondary" ?disabled=${!r.data} @click=${() => window.print()}>Print summary</button>
    </form>`;
}

function headline(data) {
  const tours = data.tasks.by_kind.find((k) => k.kind === "tour") ?? { requested: 0, done: 0, failed: 0, cancelled: 0 };
  const w = data.waits;
  const facts = [
    ["Tours requested", tours.requested],
    ["Tours done", tours.done],
    ["Tours failed", tours.failed],
    ["Tours cancelled", tours.cancelled],
    ["Wait p50 / p95", `${seconds(w.wait_s.p50)} / ${seconds(w.wait_s.p95)}`],
    ["Tour length p50", seconds(w.tour_length_s.p50)],
    ["Stopped following", `${share(data.following.share)} of ${data.following.tours}`],
  ];
  return html`<dl class="report-headline" aria-label="Headline figures">
    ${facts.map(([label, value]) => html`<div><dt>${label}</dt><dd>${value}</dd></div>`)}</dl>`;
}

function legend(series) {
  return html`<ul class="chart-legend">${series.map(([, label, colour]) => html`<li><span class="swatch" style=${`background:${colour}`}></span>${label}</li>`)}</ul>`;
}

function robotsTable(ui, data) {
  const rows = data.robots.rows;
  return html`<section class="report-part wide whole">
    <h3>Robots</h3>${csvButton(ui, "robots", "robots")}
    ${legend(STATES)}
    <table aria-label="Robots' time and distance">
      <thead><tr><th scope="col">Robot</th>${STATES.map(([, label]) => html`<th scope="col">${label} (h)</th>`)}<th scope="col">Distance (km)</th><th scope="col">Share of time</th></tr></thead>
      <tbody>${rows.map((row) => {
        const total = STATES.reduce((sum, [key]) => sum + row[`${key}_s`], 0) || 1;
        return html`<tr><th scope="row">${row.robot}</th>${STATES.map(([key]) => html`<td>${hours(row[`${key}_s`])}</td>`)}
          <td>${(row.distance_m / 1000).toFixed(2)}</td>
          <td><div class="time-bar" role="img" aria-label=${STATES.map(([key, label]) => `${label} ${Math.round((100 * row[`${key}_s`]) / total)} %`).join(", ")}>
            ${STATES.map(([key, , colour]) => html`<span style=${`width:${(100 * row[`${key}_s`]) / total}%;background:${colour}`}></span>`)}</div></td></tr>`;
      })}</tbody>
    </table>
    ${rows.length ? "" : html`<p class="muted">No robot in this period.</p>`}</section>`;
}

/** A table and, when it has no row, why: one block (in .report-columns, one grid cell). */
function table(label, head, rows, empty) {
  return html`<div class="report-table"><table aria-label=${label}>
      <thead><tr>${head.map((h) => html`<th scope="col">${h}</th>`)}</tr></thead>
      <tbody>${rows.map((cells) => html`<tr>${cells.map((c) => html`<td>${c}</td>`)}</tr>`)}</tbody>
    </table>${rows.length ? "" : html`<p class="muted">${empty}</p>`}</div>`;
}

function parts(ui, data) {
  const by = (kind) => data.following.rows.filter((row) => row.by === kind).sort((a, b) => b.stopped - a.stopped);
  const following = (kind, title) => table(
    `Stopped following per ${title}`,
    [title, "Tours", "Stopped", "Share"],
    by(kind).map((row) => [followingLabel(ui, kind, row.name), row.tours, row.stopped, share(row.share)]),
    !data.following.tours ? "No tour ended in this period." : kind === "stop" ? "Nobody stopped following at any stop." : "—",
  );
  return html`
    <section class="report-part">
      <h3>Failed tasks by reason</h3>${csvButton(ui, "tasks", "tasks per hour")}
      ${table("Failed tasks by reason", ["Reason", "Tasks"], data.tasks.failed_by_reason.map((r) => [r.reason, r.count]), "No task failed.")}
    </section>
    <section class="report-part wide">
      <h3>Visitors who stopped following</h3>${csvButton(ui, "following", "stopped following")}
      <div class="report-columns">${following("tour", "Tour")}${following("lang", "Language")}${following("stop", "Stop")}</div>
    </section>
    <section class="report-part">
      <h3>Stops most listened to</h3>${csvButton(ui, "stops", "stops")}
      ${table("Stops most listened to", ["Stop", "Explanations heard"], data.stops.rows.slice(0, 10).map((r) => [poiLabel(ui, r.stop), r.listened]), "No stop explained.")}
    </section>
    ${robotsTable(ui, data)}
    <section class="report-part">
      <h3>Incidents</h3>${csvButton(ui, "incidents", "incidents")}
      ${table("Incidents", ["What", "Where / who", "Count", "Mean wait"], data.incidents.rows.map((r) => [INCIDENT_NAMES[r.type] ?? r.type, r.name, r.count, r.wait_mean_s === null ? "–" : seconds(r.wait_mean_s)]), "No incident.")}
    </section>`;
}

const HEAT_PAD_M = 2;
const HEAT_PX_PER_M = 12;

/** White-yellow (quiet) to dark red (busiest): ``share`` of the busiest count, 0..1. */
function heatColour(share) {
  const hue = 50 - 50 * share;
  const light = 88 - 53 * share;
  return `hsl(${hue} 100% ${light}%)`;
}

/** One floor of the site with each node, door and restricted area coloured by how busy it was
 * (robots reaching a node, a door's openings, an area's grants). */
function heatFloor(ui, floor, counts, most) {
  const site = ui.store.site;
  const nodes = site.nodes.filter((n) => n.floor === floor.id);
  if (!nodes.length) return "";
  const byId = new Map(nodes.map((n) => [n.id, n]));
  const xs = nodes.map((n) => n.x);
  const ys = nodes.map((n) => n.y);
  const minX = Math.min(...xs) - HEAT_PAD_M;
  const maxX = Math.max(...xs) + HEAT_PAD_M;
  const minY = Math.min(...ys) - HEAT_PAD_M;
  const maxY = Math.max(...ys) + HEAT_PAD_M;
  const Y = (y) => maxY + minY - y; // north up
  const share = (kind, id) => (most[kind] ? (counts[kind].get(id) ?? 0) / most[kind] : 0);
  const areas = (site.areas ?? []).flatMap((a) => a.nodes.filter((n) => byId.has(n)).map((n) => [a, byId.get(n)]));
  const busiest = nodes.map((n) => [n, counts.node.get(n.id) ?? 0]).filter(([, c]) => c).sort((a, b) => b[1] - a[1]).slice(0, 3);
  const label = `Floor ${floor.name || floor.id}: ${busiest.length ? `busiest ${busiest.map(([n, c]) => `${placeName(site, n.id)} (${c})`).join(", ")}` : "no robot reached a node here"}`;
  return html`<figure class="heat-floor" data-floor=${floor.id}>
    <figcaption>${floorName(site, floor.id)}</figcaption>
    <svg viewBox=${`${minX} ${minY} ${maxX - minX} ${maxY - minY}`} style=${`width: ${Math.round((maxX - minX) * HEAT_PX_PER_M)}px`} role="img" aria-label=${label}>
      ${areas.map(([a, n]) => svg`<circle cx=${n.x} cy=${Y(n.y)} r="1.6" fill=${heatColour(share("area", a.id))} opacity="0.6"><title>Area ${a.id}: ${counts.area.get(a.id) ?? 0} grants</title></circle>`)}
      ${site.edges.filter((e) => byId.has(e.a) && byId.has(e.b)).map((e) => svg`<line x1=${byId.get(e.a).x} y1=${Y(byId.get(e.a).y)} x2=${byId.get(e.b).x} y2=${Y(byId.get(e.b).y)} stroke="#9aa0a6" stroke-width="0.2"></line>`)}
      ${nodes.map((n) => svg`<circle class="heat-node" data-node=${n.id} cx=${n.x} cy=${Y(n.y)} r=${0.35 + 0.65 * share("node", n.id)} fill=${heatColour(share("node", n.id))} stroke="#5f6368" stroke-width="0.08"><title>${placeName(site, n.id)}: reached ${counts.node.get(n.id) ?? 0} times</title></circle>`)}
      ${(site.doors ?? []).filter((d) => byId.has(d.node)).map((d) => {
        const n = byId.get(d.node);
        return svg`<rect x=${n.x - 0.6} y=${Y(n.y) - 0.6} width="1.2" height="1.2" fill=${heatColour(share("door", d.id))} stroke="#1a1a1a" stroke-width="0.12"><title>${doorName(site, d.id)}: opened ${counts.door.get(d.id) ?? 0} times</title></rect>`;
      })}
    </svg></figure>`;
}

function heatMap(ui, data) {
  const site = ui.store.site;
  if (!site) return "";
  // Only what the current site has (a node since removed has no place on the plan).
  const known = {
    node: new Set(site.nodes.map((n) => n.id)),
    door: new Set((site.doors ?? []).map((d) => d.id)),
    area: new Set((site.areas ?? []).map((a) => a.id)),
  };
  const rows = data.heat.rows.filter((row) => known[row.kind]?.has(row.name));
  const counts = { node: new Map(), door: new Map(), area: new Map() };
  for (const row of rows) counts[row.kind].set(row.name, row.count);
  const most = Object.fromEntries(Object.entries(counts).map(([k, m]) => [k, Math.max(0, ...m.values())]));
  const top = rows.slice().sort((a, b) => b.count - a.count).slice(0, 5);
  const name = (row) => (row.kind === "node" ? placeName(site, row.name) : row.kind === "door" ? doorName(site, row.name) : `area ${row.name}`);
  return html`<section class="report-part wide no-print" aria-labelledby="heat-title">
    <h3 id="heat-title">Busiest places</h3>${csvButton(ui, "heat", "busiest places")}
    <p class="muted">Nodes by robots reaching them (bigger and redder: busier), doors (squares) by openings, restricted areas (halos) by grants.
      <span class="heat-scale" aria-hidden="true"><span style=${`background:${heatColour(0)}`}></span><span style=${`background:${heatColour(0.5)}`}></span><span style=${`background:${heatColour(1)}`}></span></span></p>
    <ol class="heat-top" aria-label="Busiest places">${top.map((row) => html`<li>${name(row)}: ${row.count}</li>`)}</ol>
    <div class="heat-floors">${site.floors.map((f) => heatFloor(ui, f, counts, most))}</div>
  </section>`;
}

// --- Replay: the period played back on the floor plans, from GET /api/reports/replay -----------

const SPEEDS = [1, 10, 100];
const SMOOTH_S = 120; // between two nodes reached less than this apart, a robot is drawn moving

/** Plays a replay: the state at any time ``t`` from the start state and the events up to t. */
class Player {
  constructor(ui, replay) {
    this.ui = ui;
    this.replay = replay;
    this.start = Date.parse(replay.period.start) / 1000;
    this.end = Date.parse(replay.period.end) / 1000;
    this.t = this.start;
    this.speed = 10;
    this.playing = false;
    this.frames = 0;
    this.paths = new Map(); // robot -> [[at, node], ...] for smooth moves
    for (const [robot, node] of Object.entries(replay.start.robots)) this.paths.set(robot, [[this.start, node]]);
    for (const e of replay.events) {
      if (e.kind !== "node_reached" || !e.data.robot) continue;
      if (!this.paths.has(e.data.robot)) this.paths.set(e.data.robot, []);
      this.paths.get(e.data.robot).push([e.at, e.data.node]);
    }
    this.seek(this.start);
  }

  /** The doors, locks, elevators, links and tasks at ``t``: the events since the last ``t``
   * applied (forward), or all of them again from the start state (backward). */
  seek(t) {
    t = Math.max(this.start, Math.min(this.end, t));
    if (!this.state || t < this.t) {
      const s = this.replay.start;
      this.state = { doors: new Map(Object.entries(s.doors)), locks: new Map(Object.entries(s.locks)), lifts: new Map(Object.entries(s.elevators)), busy: new Set(), gone: new Set(), alerts: 0 };
      this.next = 0;
    }
    this.t = t;
    const events = this.replay.events;
    const state = this.state;
    while (this.next < events.length && events[this.next].at <= t) {
      const e = events[this.next];
      this.next += 1;
      const d = e.data;
      if (e.kind === "door_opened" || e.kind === "door_closed") state.doors.set(d.door, e.kind === "door_opened");
      else if (e.kind === "area_granted") state.locks.set(d.area, d.robot);
      else if (e.kind === "area_released" || e.kind === "area_force_released") { if (state.locks.get(d.area) === d.robot) state.locks.delete(d.area); }
      else if (e.kind === "elevator_in_position") state.lifts.set(d.elevator, d.floor);
      else if (e.kind === "task_started" && d.robot) state.busy.add(d.robot);
      else if (e.kind.startsWith("task_") && d.robot) state.busy.delete(d.robot);
      else if (e.kind === "robot_disconnected") state.gone.add(d.robot);
      else if (e.kind === "robot_connected") state.gone.delete(d.robot);
      else if (e.kind === "alert_raised") state.alerts += 1;
      else if (e.kind === "alert_resolved") state.alerts = Math.max(0, state.alerts - 1);
    }
  }

  /** Where ``robot`` is drawn at t: on its last node, or between it and the next one. */
  where(robot, nodes) {
    const path = this.paths.get(robot) ?? [];
    let lo = -1;
    for (let i = 0; i < path.length && path[i][0] <= this.t; i += 1) lo = i;
    if (lo < 0) return null;
    const here = nodes.get(path[lo][1]);
    const next = path[lo + 1] ? nodes.get(path[lo + 1][1]) : null;
    if (!here) return null;
    if (!next || next.floor !== here.floor || path[lo + 1][0] - path[lo][0] > SMOOTH_S) return { ...here, theta: 0 };
    const f = (this.t - path[lo][0]) / (path[lo + 1][0] - path[lo][0]);
    const theta = Math.atan2(next.y - here.y, next.x - here.x);
    return { floor: here.floor, x: here.x + (next.x - here.x) * f, y: here.y + (next.y - here.y) * f, theta };
  }

  /** Show the floors at ``t`` (the slider and the browser test's scrub). */
  show(t) {
    this.seek(t);
    drawReplay(this.ui);
  }

  play() {
    if (this.playing) return;
    this.playing = true;
    let last = performance.now();
    const step = (now) => {
      const stage = document.getElementById("replay-stage");
      if (!this.playing || !stage) return (this.playing = false);
      this.seek(this.t + ((now - last) / 1000) * this.speed);
      last = now;
      this.frames += 1;
      if (this.t >= this.end) this.playing = false;
      drawReplay(this.ui);
      if (this.playing) requestAnimationFrame(step);
    };
    requestAnimationFrame(step);
  }
}

/** The replay's map: the console's Leaflet floor map (web/lib/map.js, as the Map view draws
 * the live fleet), made once per container; null until its floors are drawn. */
function replayMap(ui) {
  const r = state(ui);
  const element = document.getElementById("replay-map");
  if (!element) return null;
  if (r.replayMap?.element !== element) {
    r.replayMap?.map.map.remove(); // a container the view drew before (it was left and came back)
    const map = new FloorMap(element, (url) => ui.api.get(url));
    map.describeRobot = (s) => (s.mode === "busy" ? "on a task" : "no task");
    r.replayMap = { element, map, ready: false, shown: new Map() };
    const mine = r.replayMap;
    map.addEventListener("floor", () => drawReplay(ui));
    map.setSite(ui.store.site).then(() => {
      mine.ready = true;
      drawReplay(ui);
    });
  }
  return r.replayMap.ready ? r.replayMap : null;
}

/** Apply the player's state at its time to the map: robots (blue ring with a task), doors,
 * held areas, elevator cars. Only what changed since the last frame is set again. */
function paintReplay(ui, player, replay) {
  const { map, shown } = replay;
  const site = ui.store.site;
  const nodes = map.nodes;
  const s = player.state;
  const same = (key, value) => shown.get(key) === value || (shown.set(key, value), false);
  for (const robot of player.paths.keys()) {
    const p = s.gone.has(robot) ? null : player.where(robot, nodes);
    if (!p) {
      if (!same(`robot:${robot}`, "gone")) map.robotOffline(robot);
      continue;
    }
    const mode = s.busy.has(robot) ? "busy" : "idle";
    if (same(`robot:${robot}`, `${p.floor}|${p.x}|${p.y}|${mode}`)) continue;
    map.updateRobot({ payload: { robot, floor: p.floor, x: p.x, y: p.y, theta: p.theta ?? 0, mode }, timestamp: Date.now() / 1000 });
  }
  for (const door of site.doors ?? []) {
    if (s.doors.has(door.id) && !same(`door:${door.id}`, s.doors.get(door.id))) map.setDoor(door.id, s.doors.get(door.id));
  }
  for (const area of site.areas ?? []) {
    const holder = s.locks.get(area.id) ?? null;
    if (!same(`area:${area.id}`, holder)) map.setAreaState({ area: area.id, state: holder ? "held" : "free", holder, waiting: [] });
  }
  for (const lift of site.elevators ?? []) {
    const floor = s.lifts.get(lift.id);
    if (floor && !same(`lift:${lift.id}`, floor)) map.setElevator(lift.id, floor, false);
  }
}

function drawReplay(ui) {
  const stage = document.getElementById("replay-stage");
  const player = state(ui).player;
  if (!stage || !player) return;
  const site = ui.store.site;
  const replay = replayMap(ui);
  const toggle = () => {
    if (player.playing) player.playing = false;
    else {
      if (player.t >= player.end) player.seek(player.start);
      player.play();
    }
    drawReplay(ui);
  };
  const s = player.state;
  const onFloor = replay ? [...player.paths.keys()].filter((r) => !s.gone.has(r) && player.where(r, replay.map.nodes)?.floor === replay.map.floor) : [];
  render(
    html`<div class="replay-controls">
        <button type="button" @click=${toggle}>${player.playing ? "Pause" : "Play"}</button>
        <label>Speed <select @change=${(e) => { player.speed = Number(e.target.value); }}>
          ${SPEEDS.map((v) => html`<option value=${v} ?selected=${player.speed === v}>${v}×</option>`)}</select></label>
        <label class="replay-time">Time <input type="range" min=${player.start} max=${player.end} step="1" .value=${String(Math.round(player.t))}
          @input=${(e) => player.show(Number(e.target.value))}></label>
        <label>Floor <select @change=${(e) => replay?.map.showFloor(e.target.value)}>
          ${site.floors.map((f) => html`<option value=${f.id} ?selected=${replay?.map.floor === f.id}>${floorName(site, f.id)}</option>`)}</select></label>
        <output id="replay-clock">${dateTime(player.t)}</output>
        ${player.replay.truncated ? html`<span class="muted">(the first 200 000 events only)</span>` : ""}
      </div>
      <p class="muted" id="replay-on-floor">${replay ? `On this floor: ${onFloor.sort().join(", ") || "no robot"}; ${s.locks.size} area(s) held.` : "Drawing the map…"}</p>`,
    stage,
  );
  if (replay) paintReplay(ui, player, replay);
}

async function loadReplay(ui) {
  const r = state(ui);
  await ui.act("Load the replay", async () => {
    const replay = await ui.api.get(`/api/reports/replay?${query(r)}`);
    r.player = new Player(ui, replay);
  });
  requestAnimationFrame(() => drawReplay(ui));
}

/** A file written by ``guidebot replay --out FILE`` (sent by a venue to its integrator). */
async function openReplayFile(ui, input) {
  const r = state(ui);
  const [file] = input.files;
  if (!file) return;
  await ui.act(`Open ${file.name}`, async () => {
    let replay;
    try {
      replay = JSON.parse(await file.text());
    } catch {
      throw new Error("this file is not JSON");
    }
    if (replay?.guidebot_replay !== 1 || !replay.period || !Array.isArray(replay.events) || !replay.start) {
      throw new Error("this is not a replay file written by guidebot replay");
    }
    if (r.player) r.player.playing = false;
    r.player = new Player(ui, replay);
    r.player.file = file.name;
  });
  requestAnimationFrame(() => drawReplay(ui));
}

function replayPart(ui, r) {
  const p = r.data.period;
  const long = Date.parse(p.end) - Date.parse(p.start) > 24 * 3600 * 1000;
  if (r.player && !r.player.file && JSON.stringify(r.player.replay.period) !== JSON.stringify(p)) {
    r.player.playing = false;
    r.player = null;
  }
  if (r.player) requestAnimationFrame(() => drawReplay(ui));
  return html`<section class="report-part wide no-print" aria-labelledby="replay-title">
    <h3 id="replay-title">Replay</h3>
    ${long
      ? html`<p class="muted">A replay covers at most 24 hours: choose a day or a shorter range.</p>`
      : r.player ? "" : html`<button type="button" class="secondary" @click=${() => loadReplay(ui)}>Replay this period</button>`}
    <label>Open a replay file <input type="file" accept=".json,application/json" @change=${(e) => openReplayFile(ui, e.target)}></label>
    ${r.player?.file ? html`<p class="muted">Playing ${r.player.file}: ${r.player.replay.period.start.slice(0, 16).replace("T", " ")} to ${r.player.replay.period.end.slice(0, 16).replace("T", " ")}.</p>` : ""}
    <div id="replay-stage"></div>
    ${r.player ? html`<div id="replay-map" class="replay-map" role="region" aria-label="The replay on the floor map"></div>` : ""}
  </section>`;
}

const LANGUAGES = new Intl.DisplayNames(["en"], { type: "language" });

/** A "stopped following" row as staff name it: the tour's and the stop's names, the language's
 * name ("Spanish"; "English (the site's default)" for a visitor who chose none). */
function followingLabel(ui, kind, name) {
  const site = ui.store.site;
  if (kind === "tour") return site ? tourName(site, name) : name;
  if (kind === "stop") return poiLabel(ui, name);
  const tag = name === "default" ? site?.default_language : name;
  let language = tag ?? "";
  try {
    language = tag ? LANGUAGES.of(tag) ?? tag : "";
  } catch {
    // not a language tag Intl knows: its own name
  }
  return name === "default" ? `${language ? `${language} ` : ""}(the site's default)`.trim() : language;
}

function poiLabel(ui, id) {
  const poi = ui.store.site?.pois?.find((p) => p.id === id);
  return poi?.name ? `${poi.name} (${id})` : id;
}

/** Draw (or redraw) the charts once their containers are on the page. */
function drawCharts(ui) {
  const data = state(ui).data;
  if (!data) return;
  const key = JSON.stringify(data.period);
  const tours = document.getElementById("chart-tours");
  const waits = document.getElementById("chart-waits");
  if (!tours || !waits || tours.dataset.key === key) return;
  // Bin starts are the venue's wall-clock times ("2026-07-14 10:00" or a day), read and drawn
  // as this browser's: the axis shows the venue's hours wherever the browser is.
  const binStarts = (rows) => rows.map((row) => Date.parse(row.start.length === 10 ? `${row.start}T00:00` : row.start.replace(" ", "T")) / 1000);
  const width = Math.max(320, Math.min(tours.parentElement.clientWidth - 16, 900));
  const common = { width, height: 220, legend: { show: false }, cursor: { drag: { x: false, y: false } } };
  for (const el of [tours, waits]) {
    el.dataset.key = key;
    el.replaceChildren();
  }
  const rows = data.tasks.rows;
  new uPlot(
    {
      ...common,
      axes: [{ values: TIME_AXIS }, { label: "tours" }],
      hooks: tickHook,
      series: [{}, ...TASK_SERIES.map(([k, label, colour], i) => ({
        label, stroke: colour, width: 2, fill: i === 0 ? `${colour}33` : undefined,
        paths: i === 0 ? uPlot.paths.bars({ size: [0.8] }) : undefined,
      }))],
    },
    [binStarts(rows), ...TASK_SERIES.map(([k]) => rows.map((row) => row[k]))],
    tours,
  );
  const w = data.waits.rows;
  new uPlot(
    {
      ...common,
      axes: [{ values: TIME_AXIS }, { label: "minutes" }],
      hooks: tickHook,
      series: [{}, { label: "Mean wait", stroke: "#0b57d0", width: 2, spanGaps: false, points: { show: true } }],
    },
    [binStarts(w), w.map((row) => (row.wait_mean_s === null ? null : row.wait_mean_s / 60))],
    waits,
  );
}

export function reportsView(ui) {
  const r = state(ui);
  const data = r.data;
  if (!data && !r.loading && !r.error) queueMicrotask(() => load(ui));
  if (data) requestAnimationFrame(() => drawCharts(ui));
  const p = data?.period;
  const perBin = p?.bin === "day" ? "day by day" : "hour by hour";
  return html`<div class="reports">
    <h2>Reports</h2>
    ${form(ui, r)}
    ${r.loading ? html`<p class="muted" role="status">Loading the report…</p>` : ""}
    ${r.error ? html`<p class="notice error" role="alert">${r.error}</p>` : ""}
    ${data
      ? html`<p class="report-period">${ui.store.site?.name ?? "GuideBot"}: ${p.start.slice(0, 16).replace("T", " ")} to ${p.end.slice(0, 16).replace("T", " ")} (${p.tz})</p>
        ${headline(data)}
        <div class="report-charts">
          <figure class="report-chart">
            <figcaption>Tours ${perBin}</figcaption>${legend(TASK_SERIES)}
            <div id="chart-tours" role="img" aria-label=${`Tours ${perBin}: requested, done, failed and cancelled (the table in the CSV)`}></div>
          </figure>
          <figure class="report-chart">
            <figcaption>Mean wait for a robot, ${perBin} (minutes)</figcaption>
            <div id="chart-waits" role="img" aria-label=${`Mean visitor wait ${perBin}`}></div>
            ${csvButton(ui, "waits", "waits")}
          </figure>
        </div>
        ${parts(ui, data)}
        ${heatMap(ui, data)}
        ${replayPart(ui, r)}`
      : ""}
  </div>`;
}
