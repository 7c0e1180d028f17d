// The site editor's plan controller: what a click, a drag or a drop on the plan does with the
// tool chosen (select, add a node, add an edge, mark a safe spot, calibrate), and the plan's
// toolbar (floor, tools, the alarm zones shown, the calibration form).
import { html, nothing } from "lit-html";
import { toggleSafeSpot } from "/config/emergency.js";
import { newElement, round } from "/config/forms.js";

/**
 * Listen to the plan (web/config/editmap.js) and edit the draft as the tool says.
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function wirePlan(ui) {
  const { map, model, select, say } = ui;
  map.addEventListener("select", (/** @type {CustomEvent} */ e) => select(e.detail.section, e.detail.index));
  map.addEventListener("node", (/** @type {CustomEvent} */ e) => {
    if (ui.tool === "safe") {
      const on = model.doc.emergency?.safe_spots?.includes(e.detail.id);
      toggleSafeSpot(model, e.detail.id);
      ui.section = "emergency";
      ui.selected = null;
      say(`Node ${e.detail.id} ${on ? "is no longer a safe spot" : "is a safe spot"}.`);
      return;
    }
    if (ui.tool === "edge") {
      if (!ui.edgeFrom) { ui.edgeFrom = e.detail.id; say(`Edge from ${e.detail.id}: now click the other node.`); return; }
      const a = ui.edgeFrom;
      ui.edgeFrom = null;
      if (a === e.detail.id) return;
      model.edit("add edge", (d) => d.edges.push(ui.oneWay ? { a, b: e.detail.id, one_way: true } : { a, b: e.detail.id }));
      ui.section = "edges";
      ui.selected = { section: "edges", index: model.doc.edges.length - 1 };
      say(`Edge ${a} ${ui.oneWay ? "→" : "↔"} ${e.detail.id} added.`);
      return;
    }
    select("nodes", e.detail.index);
  });
  map.addEventListener("mapclick", (/** @type {CustomEvent} */ e) => {
    const { x, y } = e.detail;
    if (ui.tool === "node") {
      const node = newElement(model.doc, "nodes", { x, y, floor: ui.floor });
      model.edit("add node", (d) => d.nodes.push(node));
      select("nodes", model.doc.nodes.length - 1);
      say(`Node ${node.id} added at (${node.x}, ${node.y}).`);
    } else if (ui.tool === "calibrate" && ui.calibration) {
      ui.calibration.points.push({ x, y });
      ui.draw();
    }
  });
  map.addEventListener("nodemove", (/** @type {CustomEvent} */ e) => {
    model.edit("move node", (d) => { d.nodes[e.detail.index].x = round(e.detail.x); d.nodes[e.detail.index].y = round(e.detail.y); });
  });
  map.addEventListener("poidrop", (/** @type {CustomEvent} */ e) => {
    const { index, x, y } = e.detail;
    const onFloor = model.doc.nodes.filter((n) => n.floor === ui.floor);
    const dist = (n) => Math.hypot(n.x - x, n.y - y);
    const nearest = onFloor.reduce((best, n) => (!best || dist(n) < dist(best) ? n : best), null);
    if (nearest && dist(nearest) <= 1.5) {
      model.edit("move point", (d) => { d.pois[index].node = nearest.id; });
      return select("pois", index);
    }
    const node = newElement(model.doc, "nodes", { x, y, floor: ui.floor });
    model.edit("move point to a new node", (d) => {
      d.nodes.push(node);
      if (nearest) d.edges.push({ a: nearest.id, b: node.id });
      d.pois[index].node = node.id;
    });
    select("pois", index);
    say(`Point moved to the new node ${node.id}${nearest ? `, joined to ${nearest.id}` : ""}: check its edges.`);
  });
}

/**
 * Start calibrating floor `index`: the next two clicks on the plan are a known distance apart.
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {number} index
 */
export function startCalibration(ui, index) {
  ui.tool = "calibrate";
  ui.calibration = { index, points: [] };
  ui.floor = ui.model.doc.floors[index].id;
  ui.draw();
}

/**
 * The plan's toolbar: the floor shown, the tools, the alarm inputs covering the floor, and the
 * calibration form while calibrating.
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function planToolbar(ui) {
  const doc = ui.model.doc;
  const em = doc.emergency;
  const zonesHere = (em?.alarms ?? []).filter((a) => !a.zone?.areas?.length && (!a.zone?.floors?.length || a.zone.floors.includes(ui.floor)));
  return html`
      <label for="floor-select">Floor</label> <select id="floor-select" @change=${(e) => { ui.floor = e.target.value; ui.draw(); }}>
        ${doc.floors.map((f) => html`<option value=${f.id} ?selected=${f.id === ui.floor}>${f.name || f.id}</option>`)}</select>
      <fieldset class="tools"><legend class="sr-only">Tool</legend>
        ${[["select", "Select"], ["node", "Add node"], ["edge", "Add edge"], ["safe", "Safe spot"]].map(([t, label]) => html`
          <label class="tool"><input type="radio" name="tool" value=${t} .checked=${ui.tool === t}
            @change=${() => { ui.tool = t; ui.edgeFrom = null; ui.draw(); }}> ${label}</label>`)}
        <label class="tool"><input type="checkbox" .checked=${ui.oneWay} @change=${(e) => { ui.oneWay = e.target.checked; }}> one-way</label>
      </fieldset>
      ${zonesHere.length ? html`<span class="alarm-zone" id="alarm-zones">Alarm inputs covering this floor (configuration, not a live alarm): ${zonesHere.map((a) => `${a.id} (${a.zone?.floors?.length ? "floor" : "whole site"})`).join(", ")}</span>` : nothing}
      ${ui.calibration ? html`<form class="calibrate" @submit=${(e) => applyCalibration(ui, e)} aria-label="Calibrate the plan">
        <span>Calibrate: click two points on the plan a known distance apart (${ui.calibration.points.length} of 2).</span>
        ${ui.calibration.points.length >= 2 ? html`
          <label>Distance (m) <input name="distance" type="number" step="any" min="0" required></label>
          <label>First point x (m) <input name="x" type="number" step="any" value="0"></label>
          <label>y (m) <input name="y" type="number" step="any" value="0"></label>
          <button type="submit">Apply calibration</button>` : nothing}
        <button type="button" class="secondary" @click=${() => { ui.calibration = null; ui.tool = "select"; ui.draw(); }}>Cancel</button></form>` : nothing}`;
}

/**
 * The calibration form sent: the floor's scale and origin from the two points and the distance.
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {SubmitEvent} event
 */
function applyCalibration(ui, event) {
  event.preventDefault();
  const { model, say } = ui;
  const form = new FormData(/** @type {HTMLFormElement} */ (event.target));
  const c = ui.calibration;
  const floor = model.doc.floors[c.index];
  const s = floor.scale_px_per_m || 20;
  const [ox, oy] = floor.plan_origin ?? [0, 0];
  const px = c.points.map((p) => [(p.x - ox) * s, (p.y - oy) * s]);
  const pixels = Math.hypot(px[1][0] - px[0][0], px[1][1] - px[0][1]);
  const metres = Number(form.get("distance"));
  if (!(metres > 0) || !(pixels > 0)) return say("Give a distance in metres greater than 0, between two different points.", true);
  const scale = pixels / metres;
  const X = Number(form.get("x")) || 0;
  const Y = Number(form.get("y")) || 0;
  model.edit("calibrate floor", (d) => {
    d.floors[c.index].scale_px_per_m = round(scale * 100) / 100;
    d.floors[c.index].plan_origin = [round(X - px[0][0] / scale), round(Y - px[0][1] / scale)];
  });
  ui.calibration = null;
  ui.tool = "select";
  say(`Floor ${floor.id} calibrated: ${round(scale)} px per metre.`);
}
