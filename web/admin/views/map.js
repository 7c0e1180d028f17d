// The map view's toolbar (floor switch, legend) and details panel (what was clicked).
import { html } from "lit-html";
import { carText } from "/admin/views/building.js";
import { duration, percent } from "/lib/dom.js";
import { doorState, evacuationText, floorName, linkState, placeName, robotPlace, robotTaskId, taskLabel, waitingFor } from "/admin/names.js";

export function toolbarView(ui) {
  const { store, map } = ui;
  const floors = store.site.floors;
  const online = [...store.robots.values()].filter((r) => r.online).length;
  return html`<label for="floor-select">Floor</label>
      <select id="floor-select" @change=${(e) => map.showFloor(e.target.value)}>
        ${floors.map((f) => html`<option value=${f.id} ?selected=${f.id === map.floor}>${f.name || f.id}</option>`)}
      </select>
    <span class="legend" aria-label="Battery colours">
      <span><span class="badge ok">≥ 50 %</span></span>
      <span><span class="badge warn">20–50 %</span></span>
      <span><span class="badge bad">&lt; 20 %</span></span>
    </span>
    <span class="legend" aria-label="Ring colours">
      <span>blue ring: busy</span> <span>orange dotted: waiting (door, area, elevator)</span> <span>red: fault or door blocked</span> <span>grey dashed: not online</span>
      ${ui.store.emergency && ui.store.emergency.state !== "normal"
        ? html`<span>fire alarm, double ring: orange evacuating, green safe, red stuck</span>`
        : ""}
    </span>
    <span class="muted">${online} robot${online === 1 ? "" : "s"} online</span>`;
}

function robotDetails(ui, name) {
  const robot = ui.store.robots.get(name);
  if (!robot) return html`<p>Robot ${name} is unknown.</p>`;
  const s = robot.state ?? {};
  const link = linkState(robot);
  const where = s.node ?? robot.info?.node;
  const floor = s.floor ?? robot.info?.floor ?? ui.store.site.nodes.find((n) => n.id === where)?.floor;
  return html`<h3>Robot ${name}</h3>
    <dl>
      <dt>Connection</dt><dd>${link}</dd>
      ${robot.info?.out_of_service ? html`<dt>Service</dt><dd>out of service (gets no task but those staff send it)</dd>` : ""}
      ${evacuationText(ui.store, name) ? html`<dt>Evacuation</dt><dd class="state-evacuation">${evacuationText(ui.store, name).replace("evacuation: ", "")}</dd>` : ""}
      <dt>Mode</dt><dd>${robot.online ? s.mode ?? robot.info?.mode ?? "—" : link === "hibernating" ? "offline, hibernating" : "offline"}</dd>
      ${waitingFor(ui.store, s) ? html`<dt>Waiting</dt><dd class="state-waiting">${waitingFor(ui.store, s)}</dd>` : ""}
      <dt>Battery</dt><dd>${percent(s.battery ?? robot.info?.battery)}</dd>
      <dt>${robot.online ? "Where" : "Last seen"}</dt><dd>${s.floor ? robotPlace(ui.store.site, s) : where ? placeName(ui.store.site, where) : "—"} (${floor ? floorName(ui.store.site, floor) : "—"})</dd>
      <dt>Task</dt><dd>${taskLabel(ui.store, robotTaskId(robot))}</dd>
      <dt>Nets</dt><dd>${(s.nets ?? []).join(", ") || "none"}</dd>
    </dl>`;
}

function plainDetails(ui, kind, id) {
  const site = ui.store.site;
  const lists = { node: site.nodes, poi: site.pois, door: site.doors, elevator: site.elevators, button: site.buttons, area: site.areas };
  const item = (lists[kind] ?? []).find((x) => x.id === id);
  const lock = kind === "area" ? ui.store.locks.get(id) : null;
  const title = kind === "node" ? placeName(site, id) : item?.name || `${kind} ${id}`;
  return html`<h3>${title}</h3>
    ${item?.name || kind === "node" ? html`<p class="muted">${kind} ${id}</p>` : ""}
    ${item?.text ? html`<p class="muted">${item.text}</p>` : ""}
    ${item?.node ? html`<p>At ${placeName(site, item.node)} (node ${item.node})</p>` : ""}
    ${kind === "node" ? html`<p>${floorName(site, item.floor)}, x ${item.x} m, y ${item.y} m${item.passing_place ? ", passing place" : ""}</p>` : ""}
    ${kind === "door" ? html`<p>State: ${doorState(ui.store, id)}</p>` : ""}
    ${kind === "elevator" ? html`<p>Car: ${carText(ui.store.lifts.get(id), ui.store.site)}</p>` : ""}
    ${kind === "button" && item?.task ? html`<p>Requests: ${item.task.kind} ${Object.values(item.task.params ?? {}).join(" ")}</p>` : ""}
    ${lock
      ? html`<dl><dt>State</dt><dd class=${`state-${lock.state}`}>${lock.state.replace("_", " ")}</dd>
          <dt>Holder</dt><dd>${lock.holder ?? "—"}</dd>
          <dt>Held for</dt><dd>${lock.since ? duration(Date.now() / 1000 - lock.since) : "—"}</dd>
          <dt>Waiting</dt><dd>${lock.waiting.join(", ") || "nobody"}</dd></dl>`
      : ""}`;
}

export function detailsView(ui) {
  const selected = ui.selected;
  if (!selected) {
    return html`<h3>Details</h3><p class="muted">Select a robot, area, door, elevator, point or node on the map.</p>`;
  }
  if (selected.kind === "robot") return robotDetails(ui, selected.id);
  return plainDetails(ui, selected.kind, selected.id);
}
