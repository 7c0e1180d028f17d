// The drawing: places, transitions and arcs in SVG at their positions, problems marked on their
// element, zoom (wheel) and pan (drag the background). Tools: select and move (Shift+drag the
// background: a rubber band selects the nodes inside it), add place, add transition, add arc
// (click its source, then its target). Events go to the page's handlers.
import { html, render, svg } from "lit-html";

export const PLACE_R = 16;
const BAR = { w: 34, h: 10 };
export const GRID = 10; // positions snap to this grid

const snap = (v) => Math.round(v / GRID) * GRID;

/**
 * @typedef {object} CanvasHandlers
 * @property {(kind: "place" | "transition" | "arc", id: string) => void} select
 * @property {(kind: "place" | "transition", id: string) => void} toggle add to or drop from the group
 * @property {(ids: string[]) => void} selectMany the nodes inside a rubber band
 * @property {(tool: string, x: number, y: number) => void} add a node where the tool clicked
 * @property {(ids: string[], dx: number, dy: number) => void} move nodes by an offset
 * @property {(arcId: string, fn: (points: number[][]) => void) => void} bend edit an arc's bend points
 * @property {(source: string, target: string) => void} connect an arc between two nodes
 */

/** Distance from point p to the segment a-b. */
function distToSegment(p, a, b) {
  const dx = b.x - a.x;
  const dy = b.y - a.y;
  const len = dx * dx + dy * dy;
  const t = len ? Math.max(0, Math.min(1, ((p.x - a.x) * dx + (p.y - a.y) * dy) / len)) : 0;
  return Math.hypot(p.x - (a.x + t * dx), p.y - (a.y + t * dy));
}

/** Where a line from `from` towards `to` leaves the node drawn at `from`. */
function border(node, toward, isPlace) {
  const dx = toward.x - node.x;
  const dy = toward.y - node.y;
  const len = Math.hypot(dx, dy) || 1;
  if (isPlace) return { x: node.x + (dx / len) * PLACE_R, y: node.y + (dy / len) * PLACE_R };
  const t = Math.min(BAR.w / 2 / Math.abs(dx || 1e-9), BAR.h / 2 / Math.abs(dy || 1e-9));
  return { x: node.x + dx * Math.min(t, 1), y: node.y + dy * Math.min(t, 1) };
}

export class NetCanvas {
  /**
   * @param {HTMLElement} host
   * @param {CanvasHandlers} handlers what the page does with the person's gestures
   */
  constructor(host, handlers) {
    this.host = host;
    this.handlers = handlers;
    this.view = { x: 0, y: 0, scale: 1 };
    this.fitted = null;
    this.drag = null;
    this.pending = null; // the source of an arc being drawn
    this.band = null; // the rubber band being drawn: {x, y, w, h} in the drawing's units
    host.addEventListener("wheel", (e) => this.zoom(e), { passive: false });
  }

  /** Frame the whole net (on opening one). */
  fit(doc) {
    const nodes = [...doc.places, ...doc.transitions];
    const xs = nodes.map((n) => n.x);
    const ys = nodes.map((n) => n.y);
    const box = this.host.getBoundingClientRect();
    const minX = Math.min(0, ...xs) - 40;
    const minY = Math.min(0, ...ys) - 40;
    const w = Math.max(300, Math.max(...xs, 0) + 160 - minX);
    const h = Math.max(200, Math.max(...ys, 0) + 80 - minY);
    const scale = Math.min(1.5, (box.width || 800) / w, (box.height || 500) / h);
    this.view = { x: minX, y: minY, scale };
  }

  zoom(e) {
    e.preventDefault();
    this.zoomBy(e.deltaY < 0 ? 1.2 : 1 / 1.2, this.point(e));
  }

  /** Zoom by `factor` around the drawing's point `p` (its centre when none). */
  zoomBy(factor, p = null) {
    if (!p) {
      const box = this.host.getBoundingClientRect();
      p = { x: this.view.x + (box.width || 800) / 2 / this.view.scale, y: this.view.y + (box.height || 500) / 2 / this.view.scale };
    }
    this.view.scale *= factor;
    this.view.x = p.x - (p.x - this.view.x) / factor;
    this.view.y = p.y - (p.y - this.view.y) / factor;
    this.redraw();
  }

  /** The drawing's coordinates of a pointer event. */
  point(e) {
    const r = this.host.getBoundingClientRect();
    return { x: this.view.x + (e.clientX - r.left) / this.view.scale, y: this.view.y + (e.clientY - r.top) / this.view.scale };
  }

  redraw() {
    if (this.last) this.draw(...this.last);
  }

  draw(doc, state) {
    this.last = [doc, state];
    const { tool, selected, problems, readOnly, marking, fired } = state;
    const group = state.group ?? new Set();
    const byId = new Map([...doc.places.map((p) => [p.id, { ...p, place: true }]), ...doc.transitions.map((t) => [t.id, { ...t, place: false }])]);
    const box = this.host.getBoundingClientRect();
    const vb = `${this.view.x} ${this.view.y} ${(box.width || 800) / this.view.scale} ${(box.height || 500) / this.view.scale}`;
    const isSel = (kind, id) => selected && selected.kind === kind && selected.id === id;
    const issues = (key) => problems.get(key) ?? [];
    const background = (e) => {
      if (e.target !== e.currentTarget && !e.target.classList.contains("bg")) return;
      const p = this.point(e);
      if (tool === "select" && e.shiftKey && !readOnly) {
        this.drag = { band: true, from: p };
        this.band = { x: p.x, y: p.y, w: 0, h: 0 };
        e.currentTarget.setPointerCapture?.(e.pointerId);
        return;
      }
      if (readOnly || tool === "select" || tool === "arc") {
        this.pending = null;
        this.drag = { pan: true, start: { x: e.clientX, y: e.clientY }, view: { ...this.view }, moved: false };
        e.currentTarget.setPointerCapture?.(e.pointerId);
        return;
      }
      this.handlers.add(tool, snap(p.x), snap(p.y));
    };
    const nodeDown = (e, n) => {
      e.stopPropagation();
      if (tool === "arc" && !readOnly) {
        if (!this.pending) { this.pending = n.id; this.handlers.select(n.place ? "place" : "transition", n.id); return; }
        const from = this.pending;
        this.pending = null;
        if (from !== n.id) this.handlers.connect(from, n.id);
        return;
      }
      if (e.shiftKey && !readOnly) { this.handlers.toggle(n.place ? "place" : "transition", n.id); return; }
      const ids = group.has(n.id) && group.size > 1 ? [...group] : [n.id];
      if (ids.length === 1) this.handlers.select(n.place ? "place" : "transition", n.id);
      if (readOnly) return;
      const p = this.point(e);
      this.drag = { id: n.id, ids, dx: p.x - n.x, dy: p.y - n.y, x: n.x, y: n.y, moved: false };
      this.host.querySelector("svg").setPointerCapture?.(e.pointerId);
    };
    const move = (e) => {
      const d = this.drag;
      if (!d) return;
      if (d.band) {
        const at = this.point(e);
        this.band = { x: Math.min(at.x, d.from.x), y: Math.min(at.y, d.from.y), w: Math.abs(at.x - d.from.x), h: Math.abs(at.y - d.from.y) };
        this.redraw();
        return;
      }
      if (d.pan) {
        this.view.x = d.view.x - (e.clientX - d.start.x) / this.view.scale;
        this.view.y = d.view.y - (e.clientY - d.start.y) / this.view.scale;
        d.moved = true;
        this.redraw();
        return;
      }
      if (d.bend) {
        const at = this.point(e);
        d.x = snap(at.x);
        d.y = snap(at.y);
        d.moved = true;
        this.host.querySelector(`[data-arc="${CSS.escape(d.arc)}"] [data-bend="${d.index}"]`)?.setAttribute("transform", `translate(${d.x - d.x0} ${d.y - d.y0})`);
        return;
      }
      const p = this.point(e);
      d.x = snap(p.x - d.dx);
      d.y = snap(p.y - d.dy);
      d.moved = true;
      const shift = `translate(${d.x - byId.get(d.id).x} ${d.y - byId.get(d.id).y})`;
      for (const id of d.ids) this.host.querySelector(`[data-id="${CSS.escape(id)}"]`)?.setAttribute("transform", shift);
    };
    const up = () => {
      const d = this.drag;
      this.drag = null;
      if (d?.band) {
        const b = this.band;
        this.band = null;
        const inside = [...byId.values()].filter((n) => n.x >= b.x && n.x <= b.x + b.w && n.y >= b.y && n.y <= b.y + b.h);
        this.handlers.selectMany(inside.map((n) => n.id));
        return;
      }
      if (d?.bend) {
        if (d.moved) this.handlers.bend(d.arc, (points) => { points[d.index] = [d.x, d.y]; });
        return;
      }
      if (d && !d.pan && d.moved) this.handlers.move(d.ids, d.x - byId.get(d.id).x, d.y - byId.get(d.id).y);
    };
    const keyOnNode = (e, n) => {
      if (e.key !== "Enter" && e.key !== " ") return;
      e.preventDefault();
      if (tool === "arc" && !readOnly) return nodeDown(e, n); // source, then target
      this.handlers.select(n.place ? "place" : "transition", n.id);
    };
    const arcs = doc.arcs.map((a) => {
      const s = byId.get(a.source);
      const t = byId.get(a.target);
      if (!s || !t) return null;
      const bends = (a.points ?? []).map(([x, y]) => ({ x, y }));
      const p = border(s, bends[0] ?? t, s.place);
      const q = border(t, bends.at(-1) ?? s, t.place);
      const all = [p, ...bends, q];
      const line = all.map((v) => `${v.x},${v.y}`).join(" ");
      const mid = bends.length ? bends[Math.floor(bends.length / 2)] : { x: (p.x + q.x) / 2, y: (p.y + q.y) / 2 };
      const bad = issues(`arc:${a.id}`);
      const selectedArc = isSel("arc", a.id);
      const bendAt = (e) => {
        if (readOnly || tool !== "select") return;
        e.stopPropagation();
        const at = this.point(e);
        // the new bend goes into the segment nearest the double click
        let best = 0;
        let bestDist = Infinity;
        for (let i = 0; i < all.length - 1; i += 1) {
          const d = distToSegment(at, all[i], all[i + 1]);
          if (d < bestDist) { bestDist = d; best = i; }
        }
        this.handlers.bend(a.id, (points) => points.splice(best, 0, [snap(at.x), snap(at.y)]));
      };
      const handleDown = (e, i) => {
        e.stopPropagation();
        if (readOnly) return;
        this.drag = { bend: true, arc: a.id, index: i, x: bends[i].x, y: bends[i].y, x0: bends[i].x, y0: bends[i].y, moved: false };
        this.host.querySelector("svg").setPointerCapture?.(e.pointerId);
      };
      return svg`<g class=${`net-arc${selectedArc ? " selected" : ""}${bad.length ? " has-issue" : ""}`} data-arc=${a.id}
        @pointerdown=${(e) => { e.stopPropagation(); this.handlers.select("arc", a.id); }} @dblclick=${bendAt}>
        <title>${`arc ${a.source} → ${a.target}${a.weight > 1 ? ` (weight ${a.weight})` : ""}${bad.length ? `: ${bad.join("; ")}` : ""}`}</title>
        <polyline class="hit" points=${line}></polyline>
        <polyline class="shown" points=${line} marker-end="url(#arrow)"></polyline>
        ${a.weight > 1 ? svg`<text x=${mid.x + 4} y=${mid.y - 4}>${a.weight}</text>` : null}
        ${selectedArc && !readOnly ? bends.map((b, i) => svg`<rect class="bend" data-bend=${i} x=${b.x - 4} y=${b.y - 4} width="8" height="8"
          @pointerdown=${(e) => handleDown(e, i)}
          @dblclick=${(e) => { e.stopPropagation(); this.handlers.bend(a.id, (points) => points.splice(i, 1)); }}></rect>`) : null}</g>`;
    });
    const nodes = [...byId.values()].map((n) => {
      const key = `${n.place ? "place" : "transition"}:${n.id}`;
      const bad = issues(key);
      const label = n.name || n.id;
      const cls = `net-node ${n.place ? "place" : "transition"}${n.final ? " final" : ""}${!n.place && fired?.includes(n.id) ? " fired" : ""}${isSel(n.place ? "place" : "transition", n.id) || group.has(n.id) ? " selected" : ""}${bad.length ? " has-issue" : ""}${this.pending === n.id ? " pending" : ""}`;
      const count = marking ? marking.get(n.id) ?? 0 : n.initial; // a simulation's marking, else the initial one
      const tokens = n.place ? (count > 3 ? svg`<text x=${n.x} y=${n.y + 4} text-anchor="middle">${count}</text>`
        : [...Array(count)].map((_, i) => svg`<circle class="token" r="3.5" cx=${n.x + (count === 1 ? 0 : (i - (count - 1) / 2) * 8)} cy=${n.y}></circle>`)) : null;
      return svg`<g class=${cls} data-id=${n.id} data-kind=${n.place ? "place" : "transition"} tabindex="0" role="button"
        aria-label=${`${n.place ? "place" : "transition"} ${label}${n.place && count ? `, ${count} token(s)` : ""}${bad.length ? `, ${bad.length} problem(s)` : ""}`}
        aria-pressed=${isSel(n.place ? "place" : "transition", n.id) || group.has(n.id) ? "true" : "false"}
        @pointerdown=${(e) => nodeDown(e, n)} @keydown=${(e) => keyOnNode(e, n)}>
        <title>${bad.length ? bad.join("; ") : label}</title>
        ${n.place ? svg`<circle cx=${n.x} cy=${n.y} r=${PLACE_R}></circle>` : svg`<rect x=${n.x - BAR.w / 2} y=${n.y - BAR.h / 2} width=${BAR.w} height=${BAR.h}></rect>`}
        ${tokens}
        <text x=${n.x + (n.place ? PLACE_R : BAR.w / 2) + 5} y=${n.y + 4}>${label}${bad.length ? " ⚠" : ""}</text></g>`;
    });
    render(html`<svg xmlns="http://www.w3.org/2000/svg" viewBox=${vb} role="application" aria-label="Net drawing"
        @pointerdown=${background} @pointermove=${move} @pointerup=${up} @pointercancel=${up}>
      <defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" markerHeight="7" orient="auto-start-reverse">
        <path d="M 0 0 L 10 5 L 0 10 z" fill="#444"></path></marker></defs>
      <rect class="bg" x=${this.view.x - 5000} y=${this.view.y - 5000} width="20000" height="20000" fill="transparent"></rect>
      ${arcs}${nodes}
      ${this.band ? svg`<rect class="band" x=${this.band.x} y=${this.band.y} width=${this.band.w} height=${this.band.h}></rect>` : null}</svg>`, this.host);
  }
}
