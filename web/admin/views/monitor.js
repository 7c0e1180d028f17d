// RoboGraph monitor: the nets running on one robot (or the server's RGM), drawn from their
// PNML positions (a layered layout where a net has none), with the live marking and the last
// firings highlighted. Admins may kill a net.
import { html, svg } from "lit-html";

const HIGHLIGHT = 3; // how many of the last firings are highlighted

/** Positions for every place and transition: the PNML ones, or layers by distance from the
 * initially marked places (a net without graphics still reads left to right). */
export function layout(structure) {
  const nodes = [...structure.places, ...structure.transitions];
  if (nodes.every((n) => n.x !== null && n.y !== null)) {
    return new Map(nodes.map((n) => [n.id, { x: n.x, y: n.y }]));
  }
  const next = new Map(nodes.map((n) => [n.id, []]));
  for (const a of structure.arcs) next.get(a.source)?.push(a.target);
  const start = structure.places.filter((p) => p.initial > 0).map((p) => p.id);
  const layer = new Map();
  const queue = start.length ? [...start] : nodes.length ? [nodes[0].id] : [];
  for (const id of queue) layer.set(id, 0);
  while (queue.length) {
    const id = queue.shift();
    for (const to of next.get(id) ?? []) {
      if (!layer.has(to)) {
        layer.set(to, layer.get(id) + 1);
        queue.push(to);
      }
    }
  }
  let spare = Math.max(0, ...layer.values()) + 1;
  for (const n of nodes) if (!layer.has(n.id)) layer.set(n.id, spare++);
  const rows = new Map();
  const at = new Map();
  for (const n of nodes) {
    const l = layer.get(n.id);
    const row = rows.get(l) ?? 0;
    rows.set(l, row + 1);
    at.set(n.id, { x: 50 + l * 100, y: 40 + row * 70 });
  }
  return at;
}

export class Monitor {
  constructor(ui) {
    this.ui = ui;
    this.target = null;
    this.instances = new Map(); // instance_id -> {net, marking, firings: [{transition, time}]}
    this.structures = new Map(); // net -> structure (or a Promise while loading)
    this.off = null;
    this.error = null;
  }

  open() {
    if (!this.off) {
      this.off = this.ui.hub.on("petri_net_event", (m) => this.#event(m));
      this.ui.hub.subscribe("petri_net_event");
    }
    if (!this.target) {
      const first = [...this.ui.store.robots.values()].find((r) => r.online);
      this.select(first ? first.name : "rgm");
    }
  }

  close() {
    if (this.off) {
      this.off();
      this.off = null;
      this.ui.hub.unsubscribe("petri_net_event");
    }
  }

  async select(target) {
    this.target = target;
    this.instances = new Map();
    try {
      const running = await this.ui.api.get(`/api/nets/running?target=${encodeURIComponent(target)}`);
      for (const n of running) {
        this.instances.set(n.instance_id, { net: n.net, marking: n.marking, firings: n.firings });
        this.#structure(n.net);
      }
      this.error = null;
    } catch (err) {
      this.error = err.message;
    }
    this.ui.draw();
  }

  async #structure(net) {
    if (this.structures.has(net)) return;
    this.structures.set(net, null);
    try {
      this.structures.set(net, await this.ui.api.get(`/api/nets/${encodeURIComponent(net)}/structure`));
    } catch (err) {
      this.structures.set(net, { error: err.message });
    }
    this.ui.draw();
  }

  #event(m) {
    if ((m.source || "rgm") !== this.target) return;
    const p = m.payload;
    if (p.kind === "ended") {
      this.instances.delete(p.instance_id);
    } else {
      let inst = this.instances.get(p.instance_id);
      if (!inst) {
        inst = { net: p.net, marking: {}, firings: [] };
        this.instances.set(p.instance_id, inst);
        this.#structure(p.net);
      }
      Object.assign(inst.marking, p.marking);
      if (p.kind === "fired" && p.transition) inst.firings = [...inst.firings, { transition: p.transition, time: p.time }].slice(-8);
    }
    this.ui.store.changed();
  }
}

function drawNet(structure, inst) {
  const at = layout(structure);
  const xs = [...at.values()].map((p) => p.x);
  const ys = [...at.values()].map((p) => p.y);
  const width = Math.max(...xs) + 60;
  const height = Math.max(...ys) + 50;
  const fired = new Set(inst.firings.slice(-HIGHLIGHT).map((f) => f.transition));
  const marked = structure.places.filter((p) => (inst.marking[p.id] ?? 0) > 0).map((p) => `${p.name}: ${inst.marking[p.id]}`);
  return html`<svg class="net" viewBox=${`0 0 ${width} ${height}`} width=${width} height=${height} role="img"
      aria-label=${`Net ${structure.net}; marked places: ${marked.join(", ") || "none"}`}>
    <defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="6" markerHeight="6" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="#444"/></marker></defs>
    ${structure.arcs.map((a) => {
      const s = at.get(a.source);
      const t = at.get(a.target);
      if (!s || !t) return "";
      const dx = t.x - s.x;
      const dy = t.y - s.y;
      const len = Math.hypot(dx, dy) || 1;
      const cut = 17;
      return svg`<line class="net-arc" x1=${s.x + (dx / len) * cut} y1=${s.y + (dy / len) * cut} x2=${t.x - (dx / len) * cut} y2=${t.y - (dy / len) * cut} marker-end="url(#arrow)"/>`;
    })}
    ${structure.places.map((p) => {
      const xy = at.get(p.id);
      const tokens = inst.marking[p.id] ?? 0;
      return svg`<g class=${`net-place${tokens ? " marked" : ""}`} data-place=${p.id} data-tokens=${tokens}>
        <title>${p.name}: ${tokens} token${tokens === 1 ? "" : "s"}</title>
        <circle cx=${xy.x} cy=${xy.y} r="15"/>
        ${tokens ? svg`<text x=${xy.x} y=${xy.y + 5} text-anchor="middle" class="tokens">${tokens}</text>` : ""}
        <text x=${xy.x} y=${xy.y + 30} text-anchor="middle" class="label">${p.name}</text></g>`;
    })}
    ${structure.transitions.map((t) => {
      const xy = at.get(t.id);
      return svg`<g class=${`net-transition${fired.has(t.id) ? " fired" : ""}`} data-transition=${t.id}>
        <title>${t.name}</title>
        <rect x=${xy.x - 5} y=${xy.y - 15} width="10" height="30"/>
        <text x=${xy.x} y=${xy.y - 20} text-anchor="middle" class="label">${t.name}</text></g>`;
    })}
  </svg>`;
}

export function monitorView(ui) {
  const monitor = ui.monitor;
  const robots = [...ui.store.robots.keys()].sort();
  const kill = (id, net) =>
    ui.act(`Kill ${net}`, () => ui.api.post("/api/nets/kill", { target: monitor.target, instance_id: id }));
  return html`<h2>RoboGraph monitor</h2>
    <label for="monitor-target">Show the nets of</label>
    <select id="monitor-target" @change=${(e) => monitor.select(e.target.value)}>
      ${robots.map((r) => html`<option value=${r} ?selected=${monitor.target === r}>${r}</option>`)}
      <option value="rgm" ?selected=${monitor.target === "rgm"}>Server (RGM)</option>
    </select>
    ${monitor.error ? html`<p class="notice error" role="alert">${monitor.error}</p>` : ""}
    ${monitor.instances.size ? "" : html`<p class="muted">No net is running on ${monitor.target}.</p>`}
    ${[...monitor.instances].map(([id, inst]) => {
      const structure = monitor.structures.get(inst.net);
      return html`<section class="net-card" aria-label=${`Net ${inst.net}`}>
        <h3>${inst.net} <span class="muted">${id}</span></h3>
        <p class="muted">Last firings: ${inst.firings.slice(-HIGHLIGHT).map((f) => f.transition).join(" → ") || "none yet"}</p>
        ${ui.admin ? html`<button type="button" class="danger" @click=${() => kill(id, inst.net)}>Kill ${inst.net}</button>` : ""}
        ${structure?.error ? html`<p class="error">${structure.error}</p>` : structure ? drawNet(structure, inst) : html`<p>Loading…</p>`}
      </section>`;
    })}`;
}
