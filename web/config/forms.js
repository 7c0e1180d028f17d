// The element kinds an installer edits and their forms (lit-html: text goes in as text).
// Fields not described here (e.g. per-language texts another page added to the site file)
// are still editable: a group of strings gets one box per key, anything else JSON.
import { html, nothing } from "lit-html";

const num = (v) => (v === "" || v === null || v === undefined ? null : Number(v));

export const KINDS = {
  floors: { label: "Floors", one: "floor", fields: ["id", "name", ["level", "int"], "plan_image", ["scale_px_per_m", "num"], ["plan_origin", "pair"]] },
  nodes: { label: "Nodes", one: "node", fields: ["id", ["floor", "floor"], ["x", "num"], ["y", "num"], ["passing_place", "bool"]] },
  edges: { label: "Edges", one: "edge", fields: [["a", "node"], ["b", "node"], ["one_way", "bool"], ["steps", "bool"], ["length_m", "optnum"]] },
  pois: { label: "Points of interest", one: "point", fields: ["id", "name", ["node", "node"], ["text", "area"], "lang", ["media", "media"], ["sign_video", "video"]] },
  tours: { label: "Tours", one: "tour", fields: ["id", "name", ["description", "area"], ["points", "points"]] },
  charging_stations: { label: "Charging stations", one: "station", fields: ["id", ["node", "node"]] },
  wait_points: { label: "Wait points", one: "wait point", fields: ["id", ["node", "node"]] },
  areas: { label: "Restricted areas", one: "area", fields: ["id", ["nodes", "nodes"], ["passing_place", "optnode"]] },
  doors: { label: "Doors", one: "door", fields: ["id", ["node", "node"]] },
  elevators: { label: "Elevators", one: "elevator", fields: ["id", ["travel_time_s", "num"]] },
  buttons: { label: "Building buttons", one: "button", fields: ["id", ["node", "optnode"]] },
  modules: { label: "Modbus modules", one: "module", fields: ["id", "host", ["port", "int"], ["unit_id", "int"]] },
  robots: { label: "Robots", one: "robot", fields: ["name", ["start_node", "optnode"], ["max_speed_mps", "num"], ["battery_low", "num"], ["battery_panic", "num"], ["token", "token"]] },
};

/** A fresh element of a kind (ids made unique), placed at `at` ({x, y, floor}) for nodes. */
export function newElement(doc, section, at = null) {
  const used = new Set((doc[section] ?? []).map((e) => e.id ?? e.name));
  const id = (prefix) => {
    let i = 1;
    while (used.has(`${prefix}${i}`)) i += 1;
    return `${prefix}${i}`;
  };
  const node = doc.nodes[0]?.id ?? "";
  switch (section) {
    case "floors": return { id: id("F"), name: "New floor", level: Math.max(0, ...doc.floors.map((f) => f.level ?? 0)) + 1 };
    case "nodes": return { id: id("n"), floor: at?.floor ?? doc.floors[0].id, x: round(at?.x ?? 0), y: round(at?.y ?? 0) };
    case "edges": return { a: node, b: doc.nodes[1]?.id ?? node };
    case "pois": return { id: id("poi"), name: "New point", node, text: "" };
    case "tours": return { id: id("tour"), name: "New tour", points: doc.pois[0] ? [doc.pois[0].id] : [] };
    case "charging_stations": return { id: id("station"), node };
    case "wait_points": return { id: id("wait"), node };
    case "areas": return { id: id("area"), nodes: [node] };
    case "doors": return { id: id("door"), node, open: { module: "", point: "" }, is_open: { module: "", point: "" } };
    case "elevators": return { id: id("lift"), travel_time_s: 10, stops: [] };
    case "buttons": return { id: id("button"), module: "", point: "", task: { kind: "go_to", params: {} } };
    case "modules": return { id: id("module"), host: "127.0.0.1", port: 502, unit_id: 1, points: [] };
    case "robots": return { name: id("R"), token: "change-me-" + Math.random().toString(36).slice(2, 12), start_node: node };
    default: return { id: id("x") };
  }
}

export const round = (v) => Math.round(v * 100) / 100;

/** Rename an id everywhere the site refers to it (nodes and points of interest). */
export function renameRefs(doc, section, from, to) {
  const swap = (v) => (v === from ? to : v);
  if (section === "nodes") {
    for (const e of doc.edges) { e.a = swap(e.a); e.b = swap(e.b); }
    for (const s of ["pois", "charging_stations", "wait_points", "doors", "buttons"]) {
      for (const item of doc[s] ?? []) if ("node" in item) item.node = swap(item.node);
    }
    for (const a of doc.areas ?? []) { a.nodes = a.nodes.map(swap); a.passing_place = swap(a.passing_place); }
    for (const l of doc.elevators ?? []) for (const s of l.stops ?? []) s.node = swap(s.node);
    for (const r of doc.robots ?? []) r.start_node = swap(r.start_node);
    for (const m of doc.modules ?? []) for (const p of m.points ?? []) if ("node" in p) p.node = swap(p.node);
  }
  if (section === "pois") for (const t of doc.tours ?? []) t.points = t.points.map(swap);
}

function describe(field) {
  return Array.isArray(field) ? field : [field, "text"];
}

/**
 * The form of one element. `ctx`: {doc, section, index, issues, edit(label, fn), upload(kind),
 * regenerate(name), movePoint(tourIndex, from, to)}.
 */
export function elementForm(ctx) {
  const { doc, section, index } = ctx;
  const item = doc[section][index];
  const kind = KINDS[section];
  const known = new Set(kind.fields.map((f) => describe(f)[0]));
  const fid = (name) => `f-${section}-${index}-${name}`;
  const set = (name, value) => ctx.edit(`${kind.one} ${name}`, (d) => {
    const el = d[section][index];
    const old = el[name];
    if (value === null || value === undefined) delete el[name];
    else el[name] = value;
    if ((name === "id") && old !== value) renameRefs(d, section, old, value);
  });
  const nodeOptions = (current, optional) => html`
    ${optional ? html`<option value="" ?selected=${!current}>(none)</option>` : nothing}
    ${doc.nodes.map((n) => html`<option value=${n.id} ?selected=${n.id === current}>${n.id} (${n.floor})</option>`)}`;
  const issuesOf = (name) => ctx.issues.filter((i) => i.loc.split(".")[1]?.startsWith(name));
  const field = (f) => {
    const [name, type] = describe(f);
    const value = item[name];
    const bad = issuesOf(name);
    const note = bad.length
      ? html`<span class="field-issue" id=${`${fid(name)}-issue`}>${bad.map((b) => b.msg).join("; ")}</span>`
      : nothing;
    const aria = { invalid: bad.length ? "true" : "false", desc: bad.length ? `${fid(name)}-issue` : nothing };
    switch (type) {
      case "bool":
        return html`<div class="field"><label><input type="checkbox" .checked=${!!value} @change=${(e) => set(name, e.target.checked)}> ${name.replace(/_/g, " ")}</label>${note}</div>`;
      case "num": case "int": case "optnum":
        return html`<div class="field"><label for=${fid(name)}>${name.replace(/_/g, " ")}</label>
          <input id=${fid(name)} type="number" step=${type === "int" ? "1" : "any"} .value=${value ?? ""} aria-invalid=${aria.invalid} aria-describedby=${aria.desc}
            @change=${(e) => set(name, type === "optnum" ? num(e.target.value) : num(e.target.value) ?? 0)}>${note}</div>`;
      case "pair":
        return html`<div class="field"><span class="label">${name.replace(/_/g, " ")} (m)</span>
          <label>x <input type="number" step="any" .value=${String(value?.[0] ?? 0)} @change=${(e) => set(name, [num(e.target.value) ?? 0, value?.[1] ?? 0])}></label>
          <label>y <input type="number" step="any" .value=${String(value?.[1] ?? 0)} @change=${(e) => set(name, [value?.[0] ?? 0, num(e.target.value) ?? 0])}></label>${note}</div>`;
      case "floor":
        return html`<div class="field"><label for=${fid(name)}>floor</label>
          <select id=${fid(name)} @change=${(e) => set(name, e.target.value)}>${doc.floors.map((fl) => html`<option value=${fl.id} ?selected=${fl.id === value}>${fl.name || fl.id}</option>`)}</select>${note}</div>`;
      case "node": case "optnode":
        return html`<div class="field"><label for=${fid(name)}>${name.replace(/_/g, " ")}</label>
          <select id=${fid(name)} aria-invalid=${aria.invalid} aria-describedby=${aria.desc} @change=${(e) => set(name, e.target.value || null)}>${nodeOptions(value, type === "optnode")}</select>${note}</div>`;
      case "nodes":
        return html`<div class="field"><label for=${fid(name)}>nodes (comma separated)</label>
          <input id=${fid(name)} .value=${(value ?? []).join(", ")} aria-invalid=${aria.invalid} aria-describedby=${aria.desc}
            @change=${(e) => set(name, e.target.value.split(",").map((s) => s.trim()).filter(Boolean))}>${note}</div>`;
      case "area":
        return html`<div class="field"><label for=${fid(name)}>${name}</label>
          <textarea id=${fid(name)} rows="3" .value=${value ?? ""} @change=${(e) => set(name, e.target.value)}></textarea>${note}</div>`;
      case "media":
        return html`<div class="field"><span class="label">media</span>
          <ul class="plain">${(value ?? []).map((m, i) => html`<li>${m} <button type="button" class="secondary small" @click=${() => set(name, value.filter((_, j) => j !== i))}>Remove</button></li>`)}</ul>
          <label>Upload media <input type="file" accept="image/png,image/jpeg,image/svg+xml,audio/mpeg,video/mp4" @change=${(e) => ctx.upload("media", e.target, (path) => set(name, [...(value ?? []), path]))}></label>${note}</div>`;
      case "video":
        return html`<div class="field"><span class="label">${name.replace(/_/g, " ")}</span>
          ${value ? html`<p>${value} <button type="button" class="secondary small" @click=${() => set(name, null)}>Remove</button></p>` : nothing}
          <label>Upload a sign-language video <input type="file" accept="video/mp4" @change=${(e) => ctx.upload("media", e.target, (path) => set(name, path))}></label>${note}</div>`;
      case "token":
        return html`<div class="field"><span class="label">token</span>
          <span class="muted">${value && /^[0-9a-f]{64}$/.test(value) ? "set (only its digest is kept)" : "plain (hashed when published)"}</span>
          <button type="button" class="secondary" @click=${() => ctx.regenerate(item.name)}>Regenerate token</button></div>`;
      case "points":
        return pointsField(ctx, item, note);
      default:
        return html`<div class="field"><label for=${fid(name)}>${name.replace(/_/g, " ")}</label>
          <input id=${fid(name)} .value=${value ?? ""} aria-invalid=${aria.invalid} aria-describedby=${aria.desc} @change=${(e) => set(name, e.target.value)}>${note}</div>`;
    }
  };
  const extra = Object.keys(item).filter((k) => !known.has(k));
  const extraField = (name) => {
    const value = item[name];
    if (value && typeof value === "object" && !Array.isArray(value) && Object.values(value).every((v) => typeof v === "string")) {
      return html`<fieldset class="field"><legend>${name} (per language)</legend>
        ${Object.entries(value).map(([k, v]) => html`<label class="block">${k}
          <textarea rows="2" .value=${v} @change=${(e) => set(name, { ...value, [k]: e.target.value })}></textarea></label>`)}</fieldset>`;
    }
    const bad = issuesOf(name);
    return html`<div class="field"><label for=${fid(name)}>${name.replace(/_/g, " ")} (JSON)</label>
      <textarea id=${fid(name)} rows="3" class="json" .value=${JSON.stringify(value)} aria-invalid=${bad.length ? "true" : "false"}
        @change=${(e) => { try { set(name, JSON.parse(e.target.value)); } catch { e.target.setCustomValidity("not valid JSON"); e.target.reportValidity(); } }}></textarea>
      ${bad.length ? html`<span class="field-issue">${bad.map((b) => `${b.loc.split(".").slice(1).join(".")}: ${b.msg}`).join("; ")}</span>` : nothing}</div>`;
  };
  const title = section === "edges" ? `${item.a} ${item.one_way ? "→" : "↔"} ${item.b}` : item.name || item.id;
  return html`<form class="element-form" aria-label=${`${kind.one} ${title}`} @submit=${(e) => e.preventDefault()}>
    <h3>${kind.one} ${title}</h3>
    ${ctx.issues.length ? html`<div class="notice error" role="alert">${ctx.issues.map((i) => html`<div>${i.loc}: ${i.msg}</div>`)}</div>` : nothing}
    ${kind.fields.map(field)} ${extra.map(extraField)}
    ${section === "floors" ? html`<div class="field"><label>Upload plan (PNG, JPEG or SVG)
        <input type="file" accept="image/png,image/jpeg,image/svg+xml" @change=${(e) => ctx.upload("plan", e.target, (path) => set("plan_image", path))}></label>
        <button type="button" class="secondary" @click=${() => ctx.calibrate(index)}>Calibrate scale…</button></div>` : nothing}
    <button type="button" class="danger" @click=${() => ctx.remove(section, index)}>Delete ${kind.one}</button>
  </form>`;
}

function pointsField(ctx, tour, note) {
  const { doc, index } = ctx;
  const points = tour.points ?? [];
  const names = new Map(doc.pois.map((p) => [p.id, p.name || p.id]));
  const move = (from, to) => ctx.edit("reorder tour", (d) => {
    const list = d.tours[index].points;
    const [p] = list.splice(from, 1);
    list.splice(to, 0, p);
  });
  let dragged = null;
  const onKey = (e, i) => {
    if (e.altKey && e.key === "ArrowUp" && i > 0) { e.preventDefault(); move(i, i - 1); }
    if (e.altKey && e.key === "ArrowDown" && i < points.length - 1) { e.preventDefault(); move(i, i + 1); }
  };
  const add = (e) => {
    const select = e.target.closest(".field").querySelector("select");
    if (select.value) ctx.edit("add point to tour", (d) => d.tours[index].points.push(select.value));
  };
  return html`<div class="field"><span class="label" id="tour-points-label">Points, in order (drag, or Alt+↑/↓)</span>
    <ol class="tour-points" aria-labelledby="tour-points-label">
      ${points.map((p, i) => html`<li draggable="true" tabindex="0" data-point=${p}
          class=${names.has(p) ? "" : "has-issue"}
          aria-label=${`${i + 1}. ${names.get(p) ?? p}${names.has(p) ? "" : " (unknown point)"}`}
          @keydown=${(e) => onKey(e, i)}
          @dragstart=${(e) => { dragged = i; e.dataTransfer.effectAllowed = "move"; }}
          @dragover=${(e) => e.preventDefault()}
          @drop=${(e) => { e.preventDefault(); if (dragged !== null && dragged !== i) move(dragged, i); dragged = null; }}>
        <span class="handle" aria-hidden="true">⠿</span>
        <span>${names.get(p) ?? p}${names.has(p) ? "" : html` <strong class="error">unknown point ${p}</strong>`}</span>
        <button type="button" class="secondary small" aria-label=${`Move ${names.get(p) ?? p} up`} ?disabled=${i === 0} @click=${() => move(i, i - 1)}>↑</button>
        <button type="button" class="secondary small" aria-label=${`Move ${names.get(p) ?? p} down`} ?disabled=${i === points.length - 1} @click=${() => move(i, i + 1)}>↓</button>
        <button type="button" class="secondary small" aria-label=${`Remove ${names.get(p) ?? p} from the tour`} @click=${() => ctx.edit("remove point from tour", (d) => d.tours[index].points.splice(i, 1))}>✕</button>
      </li>`)}
    </ol>
    <label>Point to add <select>${doc.pois.map((p) => html`<option value=${p.id}>${p.name || p.id}</option>`)}</select></label>
    <button type="button" @click=${add}>Add to tour</button>${note}</div>`;
}
