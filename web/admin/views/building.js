// Building: every Modbus module with health and live inputs/outputs; doors and elevators (where
// each car is, from the server's elevator_state); the building simulator's buttons when one is
// configured; the fire alarm's section (views/emergency.js).
import { html } from "lit-html";
import { doorState, floorName } from "/admin/names.js";
import { emergencySection } from "/admin/views/emergency.js";

const BITS = new Set(["discrete_input", "coil"]);

/** Where a car is (elevator_state): its floor and door, or where it is called to; floors by
 * the names the rest of the console uses ("Ground floor", not "F0"). */
export function carText(car, site) {
  if (!car || car.state === "unknown") return "not seen at a floor yet";
  const named = (floors) => floors.map((f) => floorName(site, f)).join(", ");
  const to = car.calls.filter((f) => f !== car.floor);
  if (car.state === "moving") return `moving to ${named(to)}${car.floor ? ` (last at ${floorName(site, car.floor)})` : ""}`;
  const called = car.calls.length ? `, called to ${named(car.calls)}` : "";
  return `at ${floorName(site, car.floor)}, door ${car.door_open ? "open" : "closed"}${called}`;
}

function moduleSection(ui, module) {
  const health = ui.store.building.modules.get(module.id);
  const online = health?.online;
  return html`<section aria-labelledby=${`module-${module.id}`}>
    <h3 id=${`module-${module.id}`}>${module.id}
      <span class=${`badge ${online ? "ok" : online === false ? "bad" : "warn"}`}>${online ? "online" : online === false ? "offline" : "unknown"}</span></h3>
    <p class="muted">${module.host}:${module.port}, unit ${module.unit_id}${health ? `, round trip ${health.rtt_ms ?? "—"} ms, ${health.errors ?? 0} errors${health.last_error ? `, last: ${health.last_error}` : ""}` : ""}</p>
    <table aria-label=${`Points of ${module.id}`}>
      <thead><tr><th scope="col">Point</th><th scope="col">Kind</th><th scope="col">Address</th><th scope="col">Node</th><th scope="col">Value</th></tr></thead>
      <tbody>${module.points.map((p) => {
        const value = ui.store.building.points.get(`${module.id}/${p.name}`);
        return html`<tr><td>${p.name}</td><td>${p.kind}</td><td>${p.address}</td><td>${p.node ?? "—"}</td><td data-point=${`${module.id}/${p.name}`}>${value === undefined ? "—" : BITS.has(p.kind) ? (value ? "on" : "off") : String(value)}</td></tr>`;
      })}</tbody>
    </table>
  </section>`;
}

export function buildingView(ui) {
  const site = ui.store.site;
  const press = (button) => ui.act(`Press ${button}`, () => ui.api.post("/api/building/simulator/press", { button, ms: 800 }));
  return html`<h2>Building</h2>
    ${ui.store.building.enabled ? "" : html`<p class="notice error">The building interface is not running (no modules, or disabled).</p>`}
    ${emergencySection(ui)}
    <h3>Doors</h3>
    <table aria-label="Doors">
      <thead><tr><th scope="col">Door</th><th scope="col">Node</th><th scope="col">Floor</th><th scope="col">State</th></tr></thead>
      <tbody>${site.doors.map((d) => html`<tr><td>${d.id}</td><td>${d.node}</td><td>${floorName(site, site.nodes.find((n) => n.id === d.node)?.floor)}</td><td data-door=${d.id}>${doorState(ui.store, d.id)}</td></tr>`)}</tbody>
    </table>
    <h3>Elevators</h3>
    <table aria-label="Elevators">
      <thead><tr><th scope="col">Elevator</th><th scope="col">Stops</th><th scope="col">Car</th></tr></thead>
      <tbody>${site.elevators.map((e) => {
        const car = ui.store.lifts.get(e.id);
        return html`<tr><td>${e.id}</td><td>${e.stops.map((s) => floorName(site, s.floor)).join(", ")}</td><td data-elevator=${e.id} data-floor=${car?.floor ?? ""} data-state=${car?.state ?? "unknown"}>${carText(car, site)}</td></tr>`;
      })}</tbody>
    </table>
    ${ui.store.simulator && ui.operate
      ? html`<h3>Buttons on the building simulator</h3><div class="actions">${(site.buttons ?? []).map((b) => html`<button type="button" @click=${() => press(b.id)}>Press ${b.id}</button>`)}</div>`
      : ""}
    ${site.modules.map((m) => moduleSection(ui, m))}`;
}
