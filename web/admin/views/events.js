// Event log: live, filtered by robot, person, type and severity, downloadable as JSON lines
// (admins: the audit export as CSV, docs/security.md "Audit").
import { html } from "lit-html";
import { clock } from "/admin/venue.js";
import { floorName, placeName, poiName, taskName, tourName } from "/admin/names.js";

const ERRORS = new Set(["robot_fault", "battery_panic", "task_failed", "robot_disconnected", "area_force_released", "alert_raised"]);
const WARNINGS = new Set([
  "battery_low", "area_yield", "deadlock_resolved", "task_cancelled", "alert_acked",
  "fleet_paused", "fleet_sent_home", "door_opened_by_hand", "elevator_called_by_hand",
]);

export function severity(row) {
  if (ERRORS.has(row.kind)) return "error";
  if (WARNINGS.has(row.kind)) return "warning";
  return "info";
}

/** The robot a row is about: the one it names, else the robot that sent it (any name the
 * site gives a robot: "V1" or "guide-2", not only "R<n>": a vehicle's own rows were hidden
 * when filtering by it). */
function robotOf(ui, row) {
  return row.data?.robot ?? (ui.store.robots.has(row.source) ? row.source : null);
}

/** The person (account or staff token name) a row is about: what they did, or who asked. */
function personOf(row) {
  return row.data?.account ?? row.data?.by ?? null;
}

/** A row's type for the filter: its kind's first word. A task's progress is logged as
 * "task_point 2/5 arrived" (and a handover as "task_handover: R1 at the visitor's stop 2"):
 * one type each, not one per stop and stage (the filter listed every one of the day). */
const typeOf = (row) => row.kind.split(/[\s:]/)[0];

function filtered(ui) {
  const f = ui.eventFilter ?? {};
  return ui.store.events.filter(
    (row) => (!f.robot || robotOf(ui, row) === f.robot) && (!f.person || personOf(row) === f.person)
      && (!f.kind || typeOf(row) === f.kind) && (!f.severity || severity(row) === f.severity),
  );
}

async function exportCsv(ui, person) {
  const blob = await ui.api.get(`/api/audit/export${person ? `?person=${encodeURIComponent(person)}` : ""}`);
  const url = URL.createObjectURL(blob);
  const link = document.createElement("a");
  link.href = url;
  link.download = `guidebot-events-${person || "all"}.csv`;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}

function download(rows) {
  const text = rows.map((r) => JSON.stringify(r)).join("\n") + "\n";
  const url = URL.createObjectURL(new Blob([text], { type: "application/x-ndjson" }));
  const link = document.createElement("a");
  link.href = url;
  link.download = `guidebot-events-${new Date().toISOString().slice(0, 19).replace(/:/g, "")}.jsonl`;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}

/** The row's data, ids named as the site names them (task, node, point, tour, floor). */
function summary(ui, row) {
  const d = row.data ?? {};
  const site = ui.store.site;
  const named = {
    task_id: (v) => {
      const task = ui.store.tasks.get(v);
      return ["task", task ? `${taskName(site, task)} (${v})` : v];
    },
    node: (v) => ["at", placeName(site, v)],
    poi: (v) => ["point", poiName(site, v)],
    tour: (v) => ["tour", tourName(site, v)],
    floor: (v) => ["floor", floorName(site, v)], // "First floor", as the other views say it
    // A time the sender stamped (node_reached: the robot's clock), not a place.
    at: (v) => (typeof v === "number" ? ["reported", clock(v)] : ["at", v]),
  };
  return Object.entries(d)
    .filter(([, v]) => v !== null && typeof v !== "object")
    .map(([k, v]) => (named[k] ? named[k](v) : [k, v]))
    .map(([k, v]) => `${k}=${v}`)
    .join(" ");
}

export function eventsView(ui) {
  ui.eventFilter ??= {};
  const f = ui.eventFilter;
  const set = (key) => (e) => { f[key] = e.target.value; ui.draw(); };
  const kinds = [...new Set(ui.store.events.map(typeOf))].sort();
  const people = [...new Set(ui.store.events.map(personOf).filter((p) => typeof p === "string"))].sort();
  const rows = filtered(ui);
  const shown = rows.slice(-200).reverse();
  return html`<h2>Event log</h2>
    <form class="inline" aria-label="Filter events" @submit=${(e) => e.preventDefault()}>
      <label>Robot <select @change=${set("robot")}><option value="">all</option>
        ${[...ui.store.robots.keys()].sort().map((r) => html`<option value=${r} ?selected=${f.robot === r}>${r}</option>`)}</select></label>
      <label>Person <select @change=${set("person")}><option value="">all</option>
        ${people.map((p) => html`<option value=${p} ?selected=${f.person === p}>${p}</option>`)}</select></label>
      <label>Type <select @change=${set("kind")}><option value="">all</option>
        ${kinds.map((k) => html`<option value=${k} ?selected=${f.kind === k}>${k}</option>`)}</select></label>
      <label>Severity <select @change=${set("severity")}><option value="">all</option>
        ${["info", "warning", "error"].map((s) => html`<option value=${s} ?selected=${f.severity === s}>${s}</option>`)}</select></label>
      <button type="button" @click=${() => download(rows)}>Download JSON lines</button>
      ${ui.admin ? html`<button type="button" class="secondary" @click=${() => ui.act("Export for the records", () => exportCsv(ui, f.person))}>Export CSV for the records</button>` : ""}
    </form>
    <p class="muted" id="event-count">${rows.length} events loaded (the newest 200 shown; the download has all ${rows.length}).</p>
    ${ui.store.olderEvents
      ? html`<button type="button" class="secondary" @click=${() => ui.act("Load older events", () => ui.store.loadOlderEvents())}>Load older events</button>`
      : html`<p class="muted">That is the whole event log.</p>`}
    <table aria-label="Events">
      <thead><tr><th scope="col">Time</th><th scope="col">Severity</th><th scope="col">Type</th><th scope="col">Source</th><th scope="col">Details</th></tr></thead>
      <tbody>${shown.map((r) => html`<tr><td>${clock(r.at)}</td><td>${severity(r)}</td><td>${r.kind}</td><td>${r.source}</td><td>${summary(ui, r)}</td></tr>`)}</tbody>
    </table>`;
}
