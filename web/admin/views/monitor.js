// RoboGraph monitor: the nets running on one robot (or the server's RGM), drawn where the
// server says (the PNML drawing, or a layered one for a file without graphics), labels placed
// where they overlap nothing, with zoom and pan, the live marking and the last firings
// highlighted. Admins may kill a net.
import { html, svg } from "lit-html";

const HIGHLIGHT = 3; // how many of the last firings are highlighted
const FONT_PX = 12;
const FONT = `${FONT_PX}px sans-serif`;
const LABEL_H = FONT_PX * 1.4;
const PAD = 3; // around a label and a node: no two boxes touch
const PLACE_R = 15;
const BAR = { long: 30, short: 8 }; // a transition
const FRAME_MAX_PX = 560; // the drawing's frame; pan or zoom to see the rest
const SPREADS = 10; // at most this many times the drawing is spread out to free its labels
const ZOOM = 1.25;

let measurer = null;
/** A label's width in the drawing's units (its font, measured by the browser). */
function textWidth(text) {
  measurer ??= document.createElement("canvas").getContext("2d");
  measurer.font = FONT;
  return measurer.measureText(text).width;
}

const overlap = (a, b) => a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
const area = (a, b) =>
  Math.max(0, Math.min(a.x + a.w, b.x + b.w) - Math.max(a.x, b.x)) *
  Math.max(0, Math.min(a.y + a.h, b.y + b.h) - Math.max(a.y, b.y));

/** Where each label goes: beside its node (right, left, below, above: the first spot that
 * touches no other label and no node). Returns the boxes and how many labels still overlap. */
function placeLabels(nodes) {
  const shapes = nodes.map((n) => ({ x: n.x - n.hw - PAD, y: n.y - n.hh - PAD, w: 2 * (n.hw + PAD), h: 2 * (n.hh + PAD) }));
  const placed = [];
  let clashes = 0;
  const order = nodes.map((n, i) => i).sort((a, b) => nodes[a].y - nodes[b].y || nodes[a].x - nodes[b].x);
  const boxes = new Array(nodes.length);
  for (const i of order) {
    const n = nodes[i];
    const w = textWidth(n.label) + 2 * PAD;
    const h = LABEL_H + 2 * PAD;
    const spots = [
      { x: n.x + n.hw + PAD, y: n.y - h / 2 },
      { x: n.x - n.hw - PAD - w, y: n.y - h / 2 },
      { x: n.x - w / 2, y: n.y + n.hh + PAD },
      { x: n.x - w / 2, y: n.y - n.hh - PAD - h },
    ].map((s) => ({ ...s, w, h }));
    const cost = (box) =>
      placed.reduce((sum, other) => sum + area(box, other), 0) +
      shapes.reduce((sum, shape, j) => sum + (j === i ? 0 : area(box, shape)), 0);
    let best = spots.find((box) => cost(box) === 0);
    if (!best) {
      best = spots.reduce((a, b) => (cost(b) < cost(a) ? b : a));
      if (placed.some((other) => overlap(best, other))) clashes += 1;
    }
    placed.push(best);
    boxes[i] = best;
  }
  return { boxes, clashes };
}

/** Node sizes, label boxes and bounds of a net's drawing, in the drawing's units. The server's
 * positions are kept in shape; where labels would still overlap, the drawing is spread out. */
export function drawing(structure) {
  const items = [
    ...structure.places.map((p) => ({ ...p, kind: "place" })),
    ...structure.transitions.map((t) => ({ ...t, kind: "transition" })),
  ];
  const at = new Map(items.map((n) => [n.id, { x: n.x ?? 0, y: n.y ?? 0 }]));
  // Transitions lie across the flow: a bar under a net flowing down, upright in one flowing right.
  let down = 0;
  for (const a of structure.arcs) {
    const s = at.get(a.source);
    const t = at.get(a.target);
    if (s && t) down += Math.abs(t.y - s.y) >= Math.abs(t.x - s.x) ? 1 : -1;
  }
  const across = down >= 0;
  const size = (n) =>
    n.kind === "place" ? { hw: PLACE_R, hh: PLACE_R } : across ? { hw: BAR.long / 2, hh: BAR.short / 2 } : { hw: BAR.short / 2, hh: BAR.long / 2 };
  let scale = 1;
  let nodes;
  let labels;
  for (let round = 0; ; round += 1) {
    nodes = items.map((n) => ({ id: n.id, kind: n.kind, label: n.name, x: at.get(n.id).x * scale, y: at.get(n.id).y * scale, ...size(n) }));
    labels = placeLabels(nodes);
    if (!labels.clashes || round === SPREADS) break;
    scale *= 1.2;
  }
  const byId = new Map(nodes.map((n, i) => [n.id, { ...n, box: labels.boxes[i] }]));
  const arcs = structure.arcs.map((a) => arcPath(a, byId, nodes)).filter(Boolean);
  const xs = [];
  const ys = [];
  for (const n of byId.values()) {
    xs.push(n.x - n.hw, n.x + n.hw, n.box.x, n.box.x + n.box.w);
    ys.push(n.y - n.hh, n.y + n.hh, n.box.y, n.box.y + n.box.h);
  }
  for (const a of arcs) {
    xs.push(a.cx);
    ys.push(a.cy);
  }
  const margin = 10;
  if (!xs.length) {
    // A net with nothing to draw still gets a frame.
    xs.push(0, 100);
    ys.push(0, 40);
  }
  const bounds = { x: Math.min(...xs) - margin, y: Math.min(...ys) - margin };
  bounds.w = Math.max(...xs) + margin - bounds.x;
  bounds.h = Math.max(...ys) + margin - bounds.y;
  return { nodes: byId, arcs, bounds, across, layout: structure.layout, spread: scale };
}

/** Whether the segment p-q crosses the box (Liang-Barsky clipping). */
function segmentHits(p, q, box) {
  let t0 = 0;
  let t1 = 1;
  const dx = q.x - p.x;
  const dy = q.y - p.y;
  for (const [num, den] of [[p.x - box.x, -dx], [box.x + box.w - p.x, dx], [p.y - box.y, -dy], [box.y + box.h - p.y, dy]]) {
    if (den === 0) {
      if (num < 0) return false;
    } else {
      const t = num / den;
      if (den < 0) t0 = Math.max(t0, t);
      else t1 = Math.min(t1, t);
      if (t0 > t1) return false;
    }
  }
  return true;
}

const BENDS = [0, 30, 60, 100, 150, 220, 320];

/** An arc from border to border: straight when that crosses nothing, else the least bent curve
 * (a loop back to the start of a tour, a way out that skips steps) that crosses the fewest
 * nodes, then labels; left (or up) first, away from the labels written right of the nodes. */
function arcPath(a, byId, nodes) {
  const s = byId.get(a.source);
  const t = byId.get(a.target);
  if (!s || !t) return null;
  const dx = t.x - s.x;
  const dy = t.y - s.y;
  const len = Math.hypot(dx, dy) || 1;
  let normal = { x: dy / len, y: -dx / len };
  if (normal.x > 0.1 || (Math.abs(normal.x) <= 0.1 && normal.y > 0)) normal = { x: -normal.x, y: -normal.y };
  const others = nodes.filter((n) => n.id !== s.id && n.id !== t.id);
  const shapes = others.map((n) => ({ x: n.x - n.hw - 4, y: n.y - n.hh - 4, w: 2 * n.hw + 8, h: 2 * n.hh + 8 }));
  const labels = [...byId.values()].filter((n) => n.id !== s.id && n.id !== t.id).map((n) => n.box);
  let best = null;
  for (const bend of BENDS.flatMap((b) => (b ? [b, -b] : [0]))) {
    const c = { x: (s.x + t.x) / 2 + normal.x * bend, y: (s.y + t.y) / 2 + normal.y * bend };
    const from = toward(s, bend ? c : t);
    const to = toward(t, bend ? c : s);
    const points = [];
    for (let i = 0; i <= 24; i += 1) {
      const u = i / 24;
      points.push({
        x: (1 - u) * (1 - u) * from.x + 2 * u * (1 - u) * c.x + u * u * to.x,
        y: (1 - u) * (1 - u) * from.y + 2 * u * (1 - u) * c.y + u * u * to.y,
      });
    }
    const hits = (boxes) => boxes.filter((b) => points.some((p, i) => i > 0 && segmentHits(points[i - 1], p, b))).length;
    const cost = hits(shapes) * 100 + hits(labels);
    if (!best || cost < best.cost) best = { cost, bend, c, from, to };
    if (cost === 0) break;
  }
  const { bend, c, from, to } = best;
  const d = bend ? `M ${from.x} ${from.y} Q ${c.x} ${c.y} ${to.x} ${to.y}` : `M ${from.x} ${from.y} L ${to.x} ${to.y}`;
  // The curve's own extreme (its middle) bounds the drawing, not its control point.
  return { source: a.source, target: a.target, d, cx: (s.x + t.x) / 2 + (normal.x * bend) / 2, cy: (s.y + t.y) / 2 + (normal.y * bend) / 2 };
}

/** Where the line from node n to point p leaves n's shape. */
function toward(n, p) {
  const dx = p.x - n.x;
  const dy = p.y - n.y;
  const len = Math.hypot(dx, dy) || 1;
  if (n.kind === "place") return { x: n.x + (dx / len) * PLACE_R, y: n.y + (dy / len) * PLACE_R };
  const k = Math.min(dx ? n.hw / Math.abs(dx) : Infinity, dy ? n.hh / Math.abs(dy) : Infinity);
  return { x: n.x + dx * k, y: n.y + dy * k };
}

export class Monitor {
  constructor(ui) {
    this.ui = ui;
    this.target = null;
    this.instances = new Map(); // instance_id -> {net, marking, firings: [{transition, time}]}
    this.structures = new Map(); // net -> structure (or a Promise while loading)
    this.drawings = new WeakMap(); // structure -> its drawing (labels placed once)
    this.views = new Map(); // instance_id -> the part of its drawing shown (zoom and pan)
    // instance_id -> the pan under way: kept here, not in the drawing's closure, so a live
    // redraw between pointer-down and pointer-move does not drop it.
    this.drags = new Map();
    this.off = null;
    this.error = null;
    this.loading = false; // waiting for the robots (the first snapshot) or for a target's nets
  }

  open() {
    if (!this.off) {
      this.off = this.ui.hub.on("petri_net_event", (m) => this.#event(m));
      this.ui.hub.subscribe("petri_net_event");
    }
    if (!this.target && !this.loading) {
      // The first robot online, once the snapshot has brought the robots: opened before it,
      // the monitor chose the server's own nets though R1 was online (CI).
      this.loading = true;
      this.ui.store.loaded.then(() => {
        if (this.target) return; // chosen on the page meanwhile
        const first = [...this.ui.store.robots.values()].find((r) => r.online);
        this.select(first ? first.name : "rgm");
      });
    }
  }

  close() {
    if (this.off) {
      this.off();
      this.off = null;
      this.ui.hub.unsubscribe("petri_net_event");
    }
  }

  drawingOf(structure) {
    let d = this.drawings.get(structure);
    if (!d) {
      d = drawing(structure);
      this.drawings.set(structure, d);
    }
    return d;
  }

  async select(target) {
    this.target = target;
    this.instances = new Map();
    this.views = new Map();
    this.loading = true;
    this.ui.draw();
    try {
      const running = await this.ui.api.get(`/api/nets/running?target=${encodeURIComponent(target)}`);
      if (this.target !== target) return; // another target chosen while this one was fetched
      for (const n of running) {
        this.instances.set(n.instance_id, { net: n.net, marking: n.marking, firings: n.firings });
        this.#structure(n.net);
      }
      this.error = null;
    } catch (err) {
      if (this.target !== target) return;
      this.error = err.message;
    }
    this.loading = false;
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

  /** @param {import("/lib/messages.js").Message<"petri_net_event">} m */
  #event(m) {
    if ((m.source || "rgm") !== this.target) return;
    const p = m.payload;
    if (p.kind === "ended") {
      this.instances.delete(p.instance_id);
      this.views.delete(p.instance_id);
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

/** The visible part of a drawing (its viewBox), per net instance: zoom and pan keep it. */
function frameHeight(d) {
  return Math.min(d.bounds.h, FRAME_MAX_PX);
}

function initialView(d) {
  return { x: d.bounds.x, y: d.bounds.y, w: d.bounds.w, h: frameHeight(d) };
}

function fitView(d) {
  // The whole net in the frame (its aspect kept: the frame is as wide as the net at most).
  const h = frameHeight(d);
  const k = Math.max(1, d.bounds.h / h);
  return { x: d.bounds.x, y: d.bounds.y, w: d.bounds.w * k, h: h * k };
}

function zoomed(view, factor, cx = view.x + view.w / 2, cy = view.y + view.h / 2) {
  return { x: cx - (cx - view.x) / factor, y: cy - (cy - view.y) / factor, w: view.w / factor, h: view.h / factor };
}

const viewBox = (v) => `${v.x} ${v.y} ${v.w} ${v.h}`;

function drawNet(monitor, id, structure, inst) {
  const d = monitor.drawingOf(structure);
  const view = monitor.views.get(id) ?? initialView(d);
  const set = (next, el) => {
    monitor.views.set(id, next);
    (el ?? document.querySelector(`svg[data-instance="${CSS.escape(id)}"]`))?.setAttribute("viewBox", viewBox(next));
  };
  const current = () => monitor.views.get(id) ?? initialView(d);
  const fired = new Set(inst.firings.slice(-HIGHLIGHT).map((f) => f.transition));
  const marked = structure.places.filter((p) => (inst.marking[p.id] ?? 0) > 0).map((p) => `${p.name}: ${inst.marking[p.id]}`);
  const toUser = (el, e) => {
    const m = el.getScreenCTM();
    return m ? new DOMPoint(e.clientX, e.clientY).matrixTransform(m.inverse()) : { x: 0, y: 0 };
  };
  const down = (e) => {
    monitor.drags.set(id, { el: e.currentTarget, clientX: e.clientX, clientY: e.clientY, view: current() });
    e.currentTarget.setPointerCapture?.(e.pointerId);
  };
  const move = (e) => {
    const drag = monitor.drags.get(id);
    if (!drag) return;
    // In the units of the view the drag began with: the view moves, the start point does not.
    const v = drag.view;
    const sx = v.w / (drag.el.clientWidth || v.w);
    const sy = v.h / (drag.el.clientHeight || v.h);
    const k = Math.max(sx, sy);
    const dx = (e.clientX - drag.clientX) * k;
    const dy = (e.clientY - drag.clientY) * k;
    set({ ...v, x: v.x - dx, y: v.y - dy }, drag.el);
  };
  const up = () => {
    monitor.drags.delete(id);
  };
  const wheel = (e) => {
    if (!e.ctrlKey && !e.metaKey) return; // a plain wheel scrolls the page
    e.preventDefault();
    const p = toUser(e.currentTarget, e);
    set(zoomed(current(), e.deltaY < 0 ? ZOOM : 1 / ZOOM, p.x, p.y), e.currentTarget);
  };
  const key = (e) => {
    const v = current();
    const step = v.w / 10;
    const moves = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, -step], ArrowDown: [0, step] };
    if (moves[e.key]) set({ ...v, x: v.x + moves[e.key][0], y: v.y + moves[e.key][1] }, e.currentTarget);
    else if (e.key === "+" || e.key === "=") set(zoomed(v, ZOOM), e.currentTarget);
    else if (e.key === "-") set(zoomed(v, 1 / ZOOM), e.currentTarget);
    else if (e.key === "0") set(fitView(d), e.currentTarget);
    else return;
    e.preventDefault();
  };
  const label = (n) => svg`<text x=${n.box.x + PAD} y=${n.box.y + n.box.h / 2} dominant-baseline="central" class="label" font-size=${FONT_PX}>${n.label}</text>`;
  return html`<div class="net-tools" role="group" aria-label=${`Zoom ${structure.net}`}>
      <button type="button" @click=${() => set(zoomed(current(), ZOOM))}>Zoom in</button>
      <button type="button" @click=${() => set(zoomed(current(), 1 / ZOOM))}>Zoom out</button>
      <button type="button" @click=${() => set(fitView(d))}>Whole net</button>
      <button type="button" @click=${() => set(initialView(d))}>Actual size</button>
      <span class="muted">${d.layout === "pnml" ? "Drawn as in its PNML file" : "Laid out in layers (its file has no drawing)"}; drag or use the arrow keys to pan, + and − (or Ctrl and the wheel) to zoom.</span>
    </div>
    <svg class="net" data-instance=${id} data-layout=${d.layout} data-spread=${d.spread} viewBox=${viewBox(view)} preserveAspectRatio="xMinYMin meet"
      width=${d.bounds.w} height=${frameHeight(d)} role="img" tabindex="0"
      aria-label=${`Net ${structure.net}; marked places: ${marked.join(", ") || "none"}`}
      @pointerdown=${down} @pointermove=${move} @pointerup=${up} @pointercancel=${up} @wheel=${wheel} @keydown=${key}>
    <defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="6" markerHeight="6" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="#444"/></marker></defs>
    ${d.arcs.map((a) => svg`<path class="net-arc" data-arc=${`${a.source}>${a.target}`} d=${a.d} fill="none" marker-end="url(#arrow)"/>`)}
    ${structure.places.map((p) => {
      const n = d.nodes.get(p.id);
      const tokens = inst.marking[p.id] ?? 0;
      return svg`<g class=${`net-place${tokens ? " marked" : ""}`} data-place=${p.id} data-tokens=${tokens}>
        <title>${p.name}: ${tokens} token${tokens === 1 ? "" : "s"}</title>
        <circle cx=${n.x} cy=${n.y} r=${PLACE_R}/>
        ${tokens ? svg`<text x=${n.x} y=${n.y} text-anchor="middle" dominant-baseline="central" class="tokens">${tokens}</text>` : ""}
        ${label(n)}</g>`;
    })}
    ${structure.transitions.map((t) => {
      const n = d.nodes.get(t.id);
      return svg`<g class=${`net-transition${fired.has(t.id) ? " fired" : ""}`} data-transition=${t.id}>
        <title>${t.name}</title>
        <rect x=${n.x - n.hw} y=${n.y - n.hh} width=${2 * n.hw} height=${2 * n.hh}/>
        ${label(n)}</g>`;
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
    ${monitor.loading ? html`<p class="muted">Loading the nets…</p>` : monitor.instances.size ? "" : html`<p class="muted">No net is running on ${monitor.target}.</p>`}
    ${[...monitor.instances].map(([id, inst]) => {
      const structure = monitor.structures.get(inst.net);
      return html`<section class="net-card" aria-label=${`Net ${inst.net}`}>
        <h3>${inst.net} <span class="muted">${id}</span></h3>
        <p class="muted">Last firings: ${inst.firings.slice(-HIGHLIGHT).map((f) => f.transition).join(" → ") || "none yet"}</p>
        ${ui.admin ? html`<button type="button" class="danger" @click=${() => kill(id, inst.net)}>Kill ${inst.net}</button>` : ""}
        ${structure?.error ? html`<p class="error">${structure.error}</p>` : structure ? drawNet(monitor, id, structure, inst) : html`<p>Loading…</p>`}
      </section>`;
    })}`;
}
