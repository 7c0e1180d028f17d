// Building modes: staff close a gallery (a restricted area), a set of nodes, a door or an
// elevator, now or between two times; robots drive around what is closed and tours skip the
// stops it cuts off (docs/console.md, "Building modes"). Trouble (a door that did not open, a
// lift that did not come) shows here too, and can be reopened once checked. The closed nodes
// are drawn on the map.
import { html } from "lit-html";
import { formText } from "/lib/dom.js";
import { clock, venueSeconds } from "/admin/venue.js";

const KINDS = [
  ["area", "Gallery (restricted area)"],
  ["nodes", "Nodes out of service"],
  ["door", "Door"],
  ["elevator", "Elevator"],
];

/** Keeps GET /api/closures current (closures_changed from the hub) and the map's red rings. */
export class Modes {
  constructor(ui) {
    this.ui = ui;
    this.closures = [];
    this.kind = "area";
    this.error = null;
    this.live = 0; // closures_changed messages taken: a load sent before one of them is older
  }

  async start() {
    this.ui.hub.on("closures_changed", (/** @type {import("/lib/messages.js").Message<"closures_changed">} */ m) => {
      this.live += 1;
      this.#take(m.payload.closures, m.payload.nodes);
    });
    this.ui.hub.subscribe("closures_changed");
    this.ui.hub.addEventListener("connect", () => this.load());
    await this.load();
  }

  async load() {
    const live = this.live;
    try {
      const view = await this.ui.api.get("/api/closures");
      // A closures_changed that came while it was fetched says all of them, and is newer.
      if (live === this.live) this.#take(view.closures, view.closed_nodes);
    } catch (err) {
      this.error = err.message;
      this.ui.draw();
    }
  }

  #take(closures, nodes) {
    if (this.ui.store.stopped) return; // the sign-in ended: its map is gone
    this.closures = closures;
    this.error = null;
    const closed = new Map();
    for (const node of nodes) {
      const by = closures.find((c) => c.active && c.closed_nodes?.includes(node));
      closed.set(node, by ? `${by.what} (${by.reason})` : "closed");
    }
    this.ui.map.setClosed(closed);
    this.ui.draw();
  }
}

function targets(site, kind) {
  if (kind === "area") return site.areas.map((a) => a.id);
  if (kind === "door") return site.doors.map((d) => d.id);
  if (kind === "elevator") return site.elevators.map((e) => e.id);
  return [];
}

/** A datetime-local field's value, a time at the venue, as Unix seconds (empty: null). */
function seconds(value) {
  return venueSeconds(String(value ?? ""));
}

function closeForm(ui, modes) {
  const site = ui.store.site;
  const submit = (event) => {
    event.preventDefault();
    const form = new FormData(event.target);
    const kind = form.get("kind");
    const body = {
      kind,
      reason: formText(form, "reason").trim(),
      start: seconds(form.get("start")),
      end: seconds(form.get("end")),
    };
    if (kind === "nodes") body.nodes = formText(form, "nodes").split(/[\s,]+/).filter(Boolean);
    else body.target = form.get("target");
    ui.act("Close", async () => {
      await ui.api.post("/api/closures", body);
      event.target.reset();
      modes.kind = "area";
      await modes.load();
    });
  };
  return html`<form class="close-form" @submit=${submit} aria-labelledby="close-title">
    <h3 id="close-title">Close</h3>
    <label>What <select name="kind" @change=${(e) => { modes.kind = e.target.value; ui.draw(); }}>
      ${KINDS.map(([value, label]) => html`<option value=${value} ?selected=${modes.kind === value}>${label}</option>`)}</select></label>
    ${modes.kind === "nodes"
      ? html`<label>Nodes <input name="nodes" required placeholder="gb1, gb2"></label>`
      : html`<label>Which <select name="target" required>${targets(site, modes.kind).map((id) => html`<option value=${id}>${id}</option>`)}</select></label>`}
    <label>Why (told to visitors whose tour skips a stop) <input name="reason" required maxlength="300"></label>
    <label>From <input name="start" type="datetime-local"></label>
    <label>Until <input name="end" type="datetime-local"></label>
    <p class="muted">No times: closed from now until reopened.</p>
    <button type="submit">Close it</button>
  </form>`;
}

function when(c) {
  if (c.start === null && c.end === null) return "until reopened";
  const from = c.start === null ? "now" : clock(c.start);
  return c.end === null ? `from ${from}` : `${from} to ${clock(c.end)}`;
}

export function modesView(ui) {
  const modes = ui.modes;
  const reopen = (c) => ui.act(`Reopen ${c.what}`, async () => {
    await ui.api.delete(`/api/closures/${encodeURIComponent(c.id)}`);
    await modes.load();
  });
  return html`<h2>Building modes</h2>
    <p class="muted">Robots drive around what is closed; a tour skips the stops it cuts off and tells its visitor why.</p>
    ${modes.error ? html`<p class="notice error" role="alert">Building modes could not be read: ${modes.error}</p>` : ""}
    <table aria-label="Closures">
      <thead><tr><th scope="col">Closed</th><th scope="col">Why</th><th scope="col">When</th><th scope="col">State</th><th scope="col">By</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>
        ${modes.closures.length ? "" : html`<tr><td colspan="6">Nothing is closed.</td></tr>`}
        ${modes.closures.map((c) => html`<tr>
          <td>${c.what}</td>
          <td>${c.reason}</td>
          <td>${when(c)}</td>
          <td>${c.source === "trouble" ? "trouble" : c.active ? "closed now" : "planned"}</td>
          <td>${c.by}</td>
          <td>${ui.operate ? html`<button type="button" class="secondary" @click=${() => reopen(c)}>Reopen ${c.what}</button>` : ""}</td>
        </tr>`)}
      </tbody>
    </table>
    ${ui.operate ? closeForm(ui, modes) : ""}`;
}
