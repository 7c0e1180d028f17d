// Fleet: the controls of a busy day (pause the fleet and resume, send every robot home, open
// a door or call an elevator by hand) and every floor at once, each robot where it is.
import { html, svg } from "lit-html";
import { confirmAction } from "/lib/confirm.js";
import { inputValue } from "/lib/dom.js";
import { clock } from "/admin/venue.js";
import { WAITING } from "/lib/map.js";
import { atPlace, doorName, doorState, elevatorName, floorName, lastKnown, linkState, robotDoing, robotPlace } from "/admin/names.js";
import { carText } from "/admin/views/building.js";

const PAD_M = 2;
const LABEL_M = 12; // room on the right for the names of the points there
const PX_PER_M = 16; // every floor at one scale
/** A door's fill and edge by its state (doorState): green open, red closed, grey not read yet. */
const DOOR_COLOURS = { open: ["#a8dab5", "#1b7a3a"], closed: ["#f4b6bf", "#b00020"], "not read yet": ["#e2e4e8", "#5f6368"] };

function fleetControls(ui) {
  const fleet = ui.store.fleet;
  const pause = () => ui.act("Pause the fleet", async () => {
    ui.store.takeFleet(await ui.api.post("/api/fleet/pause", { reason: inputValue("pause-reason") }));
  });
  const resume = () => ui.act("Resume the fleet", async () => {
    ui.store.takeFleet(await ui.api.post("/api/fleet/resume"));
  });
  const home = async () => {
    const ok = await confirmAction({
      title: "Send every robot home?",
      text: "Every online robot in service is sent to a charging station: at once if it has no task, after its task otherwise. Queued tasks wait for a robot that is free again.",
      confirm: "Send every robot home",
      keep: "Keep them working",
    });
    if (!ok) return;
    await ui.act("Send every robot home", async () => {
      const reply = await ui.api.post("/api/fleet/home");
      const skipped = reply.skipped.map((s) => `${s.robot} (${s.why})`).join(", ");
      if (skipped) ui.fleetNote = `Not sent: ${skipped}.`;
    });
  };
  return html`<section aria-labelledby="fleet-title">
    <h3 id="fleet-title">Fleet</h3>
    <p id="fleet-state" role="status">${fleet?.paused
      ? html`<span class="badge warn">paused</span> by ${fleet.by} at ${clock(fleet.since)}${fleet.reason ? ` (${fleet.reason})` : ""}: no robot starts a task; running tasks go on.`
      : html`<span class="badge ok">running</span> Robots take queued tasks as they become free.`}</p>
    ${ui.operate ? html`<div class="actions">
      ${fleet?.paused
        ? html`<button type="button" @click=${resume}>Resume the fleet</button>`
        : html`<label>Reason <input id="pause-reason" maxlength="200" placeholder="optional"></label>
          <button type="button" class="danger" @click=${pause}>Pause the fleet</button>`}
      <button type="button" class="secondary" @click=${home}>Send every robot home</button>
    </div>` : ""}
    ${ui.fleetNote ? html`<p class="muted">${ui.fleetNote}</p>` : ""}
  </section>`;
}

function buildingControls(ui) {
  const site = ui.store.site;
  const door = (id, action) => ui.act(`${action === "open" ? "Open" : "Close"} ${doorName(site, id)}`, () => ui.api.post(`/api/building/doors/${encodeURIComponent(id)}/${action}`));
  const call = (lift) => {
    const floor = inputValue(`call-${lift.id}`);
    return ui.act(`Call ${elevatorName(site, lift.id)} to ${floorName(site, floor)}`, () => ui.api.post(`/api/building/elevators/${encodeURIComponent(lift.id)}/call`, { floor }));
  };
  // As the Building view says it: "moving to First floor (last at Ground floor)" while it
  // moves, not "at Ground floor" (the floor it left).
  const car = (id) => carText(ui.store.lifts.get(id), site);
  return html`<section aria-labelledby="by-hand-title">
    <h3 id="by-hand-title">Doors and elevators by hand</h3>
    <table aria-label="Doors">
      <thead><tr><th scope="col">Door</th><th scope="col">Where</th><th scope="col">State</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${(site.doors ?? []).map((d) => html`<tr data-door-row=${d.id}><td>${doorName(site, d.id)}</td><td>${floorName(site, site.nodes.find((n) => n.id === d.node)?.floor)}</td><td>${doorState(ui.store, d.id)}</td>
        <td class="actions">${ui.operate ? html`<button type="button" @click=${() => door(d.id, "open")}>Open ${doorName(site, d.id)}</button>
          <button type="button" class="secondary" @click=${() => door(d.id, "close")}>Close ${doorName(site, d.id)}</button>` : ""}</td></tr>`)}</tbody>
    </table>
    <table aria-label="Elevators">
      <thead><tr><th scope="col">Elevator</th><th scope="col">Car</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${(site.elevators ?? []).map((e) => html`<tr><td>${elevatorName(site, e.id)}</td><td>${car(e.id)}</td>
        <td class="actions">${ui.operate ? html`<label for=${`call-${e.id}`} class="sr-only">Floor to call ${elevatorName(site, e.id)} to</label>
          <select id=${`call-${e.id}`}>${e.stops.map((s) => html`<option value=${s.floor}>${floorName(site, s.floor)}</option>`)}</select>
          <button type="button" @click=${() => call(e)}>Call ${elevatorName(site, e.id)}</button>` : ""}</td></tr>`)}</tbody>
    </table>
  </section>`;
}

function robotColour(ui, s) {
  if (!ui.store.robots.get(s.robot)?.online) return "#e2e4e8"; // lost: where it was last seen
  const evacuation = ui.store.evacuation(s.robot);
  if (evacuation) return evacuation.state === "safe" ? "#1b7a3a" : evacuation.state === "stuck" ? "#b00020" : "#b35900";
  if (s.mode === "fault" || s.navigation === "door_blocked") return "#b00020";
  if (WAITING.has(s.navigation)) return "#b35900";
  if (s.mode === "busy") return "#0b57d0";
  return "#1b7a3a";
}

const robotCount = (n) => `${n} robot${n === 1 ? "" : "s"}`;

/** One floor, drawn from the site's coordinates (metres, y up), with every robot on it. */
function floorPlan(ui, floor) {
  const site = ui.store.site;
  const nodes = site.nodes.filter((n) => n.floor === floor.id);
  if (!nodes.length) return "";
  const byId = new Map(nodes.map((n) => [n.id, n]));
  const xs = nodes.map((n) => n.x);
  const ys = nodes.map((n) => n.y);
  const minX = Math.min(...xs) - PAD_M;
  const maxX = Math.max(...xs) + LABEL_M;
  const minY = Math.min(...ys) - PAD_M;
  const maxY = Math.max(...ys) + PAD_M;
  const Y = (y) => maxY + minY - y; // north up
  // Online robots where they are; a lost one (as the map draws it) where it was last seen.
  const robots = [...ui.store.robots.values()]
    .map((r) => [r, lastKnown(r)])
    .filter(([r, s]) => s && (r.online || linkState(r) !== "never connected") && ui.map.pose(s).floor === floor.id);
  const placed = new Map();
  const robotMarks = robots.sort((a, b) => a[0].name.localeCompare(b[0].name)).map(([r, s]) => {
    const p = ui.map.pose(s);
    const key = `${Math.round(p.x / 0.6)},${Math.round(p.y / 0.6)}`;
    const k = placed.get(key) ?? 0;
    placed.set(key, k + 1);
    const x = p.x + k * 1.4;
    const link = linkState(r);
    const label = r.online
      ? `${r.name}: ${robotDoing(ui.store, s)}, ${atPlace(robotPlace(site, s))}`
      : `${r.name}: ${link}, last seen ${atPlace(robotPlace(site, s))}`;
    return svg`<g class="overview-robot" data-robot=${r.name} data-link=${link} role="img" aria-label=${label}><title>${label}</title>
      <circle cx=${x} cy=${Y(p.y)} r="0.8" fill=${robotColour(ui, s)} stroke=${r.online ? "#1a1a1a" : "#5f6368"} stroke-width="0.15" stroke-dasharray=${r.online ? "none" : "0.3 0.2"}></circle>
      <text x=${x} y=${Y(p.y) - 1.1} text-anchor="middle" font-size="1.1" font-weight="700" fill=${r.online ? "#1a1a1a" : "#5f6368"}>${r.online ? r.name : `${r.name} (${link})`}</text></g>`;
  });
  return html`<figure class="overview-floor" data-floor=${floor.id}>
    <figcaption>${floor.name || floor.id} · ${robotCount(robots.filter(([r]) => r.online).length)}${robots.some(([r]) => !r.online) ? `, ${robots.filter(([r]) => !r.online).length} not online` : ""}</figcaption>
    <svg viewBox=${`${minX} ${minY} ${maxX - minX} ${maxY - minY}`} style=${`width: ${Math.round((maxX - minX) * PX_PER_M)}px`} role="group" aria-label=${`Floor ${floor.name || floor.id}`}>
      ${site.edges.filter((e) => byId.has(e.a) && byId.has(e.b)).map((e) => svg`<line x1=${byId.get(e.a).x} y1=${Y(byId.get(e.a).y)} x2=${byId.get(e.b).x} y2=${Y(byId.get(e.b).y)} stroke="#9aa0a6" stroke-width="0.25"></line>`)}
      ${(site.pois ?? []).filter((p) => byId.has(p.node)).map((p) => {
        const n = byId.get(p.node);
        return svg`<circle cx=${n.x + 0.6} cy=${Y(n.y + 0.6)} r="0.4" fill="#0b57d0"></circle><text x=${n.x + 1.2} y=${Y(n.y + 0.6) + 0.35} font-size="0.9" fill="#3c4043">${p.name || p.id}</text>`;
      })}
      ${(site.doors ?? []).filter((d) => byId.has(d.node)).map((d) => {
        const n = byId.get(d.node);
        const state = doorState(ui.store, d.id);
        const [fill, stroke] = DOOR_COLOURS[state];
        return svg`<rect x=${n.x - 0.5} y=${Y(n.y) - 0.5} width="1" height="1" fill=${fill} stroke=${stroke} stroke-width="0.2"><title>${doorName(site, d.id)}: ${state}</title></rect>`;
      })}
      ${(site.elevators ?? []).flatMap((e) => e.stops.filter((st) => byId.has(st.node)).map((st) => {
        const n = byId.get(st.node);
        const car = ui.store.lifts.get(e.id);
        // A moving car is at no stop: the one it left is not "here".
        const here = car?.state !== "moving" && car?.floor === st.floor;
        const where = here ? "the car is here" : car?.state === "moving" ? `the car is ${carText(car, site)}` : "the car is elsewhere";
        return svg`<rect x=${n.x - 0.8} y=${Y(n.y) - 0.8} width="1.6" height="1.6" fill=${here ? "#8ab4f8" : "#ccc"} stroke="#444" stroke-width="0.15"><title>${elevatorName(site, e.id)}: ${where}</title></rect>`;
      }))}
      ${robotMarks}
    </svg>
  </figure>`;
}

export function fleetView(ui) {
  return html`<h2>Fleet</h2>
    ${fleetControls(ui)}
    <section aria-labelledby="floors-title">
      <h3 id="floors-title">Every floor</h3>
      <div class="overview">${ui.store.site.floors.map((f) => floorPlan(ui, f))}</div>
    </section>
    ${buildingControls(ui)}`;
}
