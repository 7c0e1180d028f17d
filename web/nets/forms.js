// The selected element's form: the net (name, description, parameters), a place (marking,
// final, its action), a transition (priority, its condition), an arc (weight). The action kinds,
// message types, their fields and the library's nets are offered as choices (the server's
// vocabulary, GET /api/net-editor/vocabulary). Every change is one undoable edit.
import { html, nothing } from "lit-html";

const none = "";

function issuesOf(ctx, key) {
  const list = ctx.problems.get(key) ?? [];
  return list.length ? html`<ul class="field-issue" aria-label="Problems of this element">${list.map((m) => html`<li>${m}</li>`)}</ul>` : nothing;
}

/**
 * A labelled control; `id` makes the label point at it (Playwright and screen readers).
 * @param {string} label
 * @param {unknown} value
 * @param {(value: any) => void} onChange
 * @param {{id?: string, type?: string, multiline?: boolean}} [how]
 */
function text(label, value, onChange, { id, type = "text", multiline = false } = {}) {
  const fid = id ?? `f-${label.replace(/\W+/g, "-").toLowerCase()}`;
  return html`<div class="field"><label for=${fid}>${label}</label>${multiline
    ? html`<textarea id=${fid} rows="4" .value=${value ?? ""} @change=${(e) => onChange(e.target.value)}></textarea>`
    : html`<input id=${fid} type=${type} .value=${value ?? ""} @change=${(e) => onChange(type === "number" ? Number(e.target.value) : e.target.value)}>`}</div>`;
}

/**
 * A labelled list of choices; a value not among them is offered as "(unknown)".
 * @param {string} label
 * @param {string | null | undefined} value
 * @param {string[]} options
 * @param {(value: string) => void} onChange
 * @param {{id?: string, empty?: string | null}} [how] its id; the empty choice's text (null: none)
 */
function choice(label, value, options, onChange, { id, empty = "(none)" } = {}) {
  const fid = id ?? `f-${label.replace(/\W+/g, "-").toLowerCase()}`;
  const known = options.includes(value) || !value;
  return html`<div class="field"><label for=${fid}>${label}</label><select id=${fid} @change=${(e) => onChange(e.target.value)}>
    ${empty === null ? nothing : html`<option value="" ?selected=${!value}>${empty}</option>`}
    ${known ? nothing : html`<option value=${value} selected>${value} (unknown)</option>`}
    ${options.map((o) => html`<option value=${o} ?selected=${o === value}>${o}</option>`)}</select></div>`;
}

function check(label, value, onChange, id) {
  return html`<div class="field"><label><input id=${id} type="checkbox" .checked=${!!value} @change=${(e) => onChange(e.target.checked)}> ${label}</label></div>`;
}

const paramNames = (doc) => doc.params.map((p) => p.name);

function netForm(ctx) {
  const { doc, edit } = ctx;
  const setParam = (i, fn) => edit("change parameter", (d) => fn(d.params[i]));
  return html`<div class="form">${issuesOf(ctx, "net")}
    ${text("Net id", doc.id, (v) => edit("rename net", (d) => { d.id = v; }), { id: "f-net-id" })}
    ${text("Name", doc.name, (v) => edit("rename net", (d) => { d.name = v; }), { id: "f-net-name" })}
    ${text("Description", doc.description, (v) => edit("describe net", (d) => { d.description = v; }), { id: "f-net-description", multiline: true })}
    ${check("Endless (runs until killed)", doc.endless, (v) => edit("endless", (d) => { d.endless = v; }), "f-net-endless")}
    <fieldset><legend>Parameters</legend>
      ${doc.params.map((p, i) => html`<div>${issuesOf(ctx, `param:${p.name}`)}
        ${text(`Parameter ${i + 1} name`, p.name, (v) => setParam(i, (q) => { q.name = v; }), { id: `f-param-${i}-name` })}
        ${check("required (no default)", p.required, (v) => setParam(i, (q) => { q.required = v; if (v) delete q.default; }), `f-param-${i}-required`)}
        ${p.required ? nothing : text(`Parameter ${i + 1} default (JSON or text)`, p.default === undefined || p.default === null ? "" : typeof p.default === "string" ? p.default : JSON.stringify(p.default),
          (v) => setParam(i, (q) => { try { q.default = JSON.parse(v); } catch { q.default = v; } }), { id: `f-param-${i}-default` })}
        ${ctx.readOnly ? nothing : html`<button type="button" class="secondary small" @click=${() => edit("delete parameter", (d) => d.params.splice(i, 1))}>Remove parameter ${p.name}</button>`}</div>`)}
      ${ctx.readOnly ? nothing : html`<button type="button" class="secondary small" @click=${() => edit("add parameter", (d) => d.params.push({ name: `param${d.params.length + 1}`, required: false, default: "" }))}>Add parameter</button>`}
    </fieldset></div>`;
}

function fieldsHint(vocab, type) {
  const fields = vocab?.message_types?.[type];
  return fields?.length ? html`<p class="muted">Fields of ${type}: ${fields.join(", ")}</p>` : nothing;
}

function actionForm(ctx, place) {
  const { doc, edit, vocabulary: v } = ctx;
  const a = place.action;
  const set = (fn) => edit("change action", (d) => fn(d.places.find((p) => p.id === place.id).action));
  const kind = choice("Action", a?.kind ?? none, v?.action_kinds ?? [], (k) => edit("change action kind", (d) => {
    d.places.find((p) => p.id === place.id).action = k ? { kind: k, body: "" } : null;
  }), { id: "f-action-kind" });
  if (!a) return kind;
  const types = Object.keys(v?.message_types ?? {});
  const parts = [];
  if (a.kind === "publish") {
    parts.push(choice("Message type", a.type, types, (t) => set((x) => { x.type = t || null; }), { id: "f-action-type" }), fieldsHint(v, a.type),
      text("Destination", a.destination, (t) => set((x) => { x.destination = t || null; }), { id: "f-action-destination" }),
      text("Payload (JSON, ${parameter} allowed)", a.body, (t) => set((x) => { x.body = t; }), { id: "f-action-body", multiline: true }));
  } else if (a.kind === "timer") {
    parts.push(text("Seconds", a.seconds, (t) => set((x) => { x.seconds = t || null; }), { id: "f-action-seconds" }));
  } else if (a.kind === "run" || a.kind === "kill") {
    parts.push(choice("Net", a.net, ctx.library, (t) => set((x) => { x.net = t || null; }), { id: "f-action-net" }));
    if (a.kind === "run") parts.push(text("Parameters (JSON object)", a.body, (t) => set((x) => { x.body = t; }), { id: "f-action-body", multiline: true }),
      text("Store its instance in variable", a.var, (t) => set((x) => { x.var = t || null; }), { id: "f-action-var" }));
  } else if (a.kind === "next") {
    parts.push(choice("List parameter", a.list, paramNames(doc), (t) => set((x) => { x.list = t || null; }), { id: "f-action-list" }),
      text("Item variable", a.var, (t) => set((x) => { x.var = t || null; }), { id: "f-action-var" }),
      choice("Order", a.order, v?.orders ?? [], (t) => set((x) => { x.order = t || null; }), { id: "f-action-order", empty: "(sequence)" }));
  }
  return html`${kind}${parts}`;
}

function conditionForm(ctx, trans) {
  const { doc, edit, vocabulary: v } = ctx;
  const c = trans.condition;
  const set = (fn) => edit("change condition", (d) => fn(d.transitions.find((t) => t.id === trans.id).condition));
  const kind = choice("Condition", c?.kind ?? none, v?.condition_kinds ?? [], (k) => edit("change condition kind", (d) => {
    d.transitions.find((t) => t.id === trans.id).condition = k ? { kind: k, matches: [], binds: [] } : null;
  }), { id: "f-condition-kind", empty: "(none: fires when enabled)" });
  if (!c) return kind;
  const types = Object.keys(v?.message_types ?? {});
  const fields = v?.message_types?.[c.type] ?? [];
  const parts = [];
  if (c.kind === "message") {
    parts.push(choice("Message type", c.type, types, (t) => set((x) => { x.type = t || null; }), { id: "f-condition-type" }),
      html`<fieldset><legend>Matches (field = value)</legend>${c.matches.map((m, i) => html`
        ${choice(`Match ${i + 1} field`, m.field, fields, (t) => set((x) => { x.matches[i].field = t; }), { id: `f-match-${i}-field`, empty: null })}
        ${text(`Match ${i + 1} value`, m.value, (t) => set((x) => { x.matches[i].value = t; }), { id: `f-match-${i}-value` })}
        <button type="button" class="secondary small" @click=${() => set((x) => x.matches.splice(i, 1))}>Remove match ${i + 1}</button>`)}
        ${fields.length ? html`<button type="button" class="secondary small" @click=${() => set((x) => x.matches.push({ field: fields[0], value: "" }))}>Add match</button>` : nothing}</fieldset>`,
      html`<fieldset><legend>Keep fields in variables</legend>${c.binds.map((b, i) => html`
        ${text(`Variable ${i + 1}`, b.var, (t) => set((x) => { x.binds[i].var = t; }), { id: `f-bind-${i}-var` })}
        ${choice(`Variable ${i + 1} field`, b.field, fields, (t) => set((x) => { x.binds[i].field = t; }), { id: `f-bind-${i}-field`, empty: null })}
        <button type="button" class="secondary small" @click=${() => set((x) => x.binds.splice(i, 1))}>Remove variable ${i + 1}</button>`)}
        ${fields.length ? html`<button type="button" class="secondary small" @click=${() => set((x) => x.binds.push({ var: fields[0], field: fields[0] }))}>Add variable</button>` : nothing}</fieldset>`);
  } else if (c.kind === "net_ended") {
    parts.push(choice("Net", c.net, ctx.library, (t) => set((x) => { x.net = t || null; }), { id: "f-condition-net" }),
      choice("Outcome", c.outcome, v?.net_outcomes ?? [], (t) => set((x) => { x.outcome = t || null; }), { id: "f-condition-outcome", empty: "(any)" }));
  } else if (c.kind === "guard") {
    const vars = [...new Set([...paramNames(doc), ...doc.places.map((p) => p.action?.var).filter(Boolean)])];
    parts.push(choice("Variable", c.var, vars, (t) => set((x) => { x.var = t || null; }), { id: "f-condition-var" }),
      choice("Test", c.test, v?.guard_tests ?? [], (t) => set((x) => { x.test = t || null; }), { id: "f-condition-test" }));
    if (c.test === "equals") parts.push(text("Value", c.value, (t) => set((x) => { x.value = t; }), { id: "f-condition-value" }));
  } else if (c.kind === "timer") {
    parts.push(html`<p class="muted">Fires when the timer of its input place runs out.</p>`);
  }
  return html`${kind}${parts}`;
}

/** The form of the selected element (fields disabled for a reader). */
export function detailsForm(ctx) {
  const { doc, selected, edit } = ctx;
  let body;
  if (selected.kind === "net") body = netForm(ctx);
  else if (selected.kind === "arc") {
    const arc = doc.arcs.find((a) => a.id === selected.id);
    body = html`${issuesOf(ctx, `arc:${arc.id}`)}<p>${arc.source} → ${arc.target}</p>
      ${text("Weight", arc.weight, (w) => edit("change weight", (d) => { d.arcs.find((a) => a.id === arc.id).weight = Math.max(1, Math.round(w) || 1); }), { id: "f-arc-weight", type: "number" })}
      <p class="muted">Bend points: ${arc.points?.length ? arc.points.map(([x, y]) => `(${x}, ${y})`).join(" → ") : "none (straight)"}.
        Double-click the arc to add one, drag it to move it, double-click it to remove it.</p>
      ${arc.points?.length ? html`<button type="button" class="secondary small" @click=${() => edit("straighten arc", (d) => { d.arcs.find((a) => a.id === arc.id).points = []; })}>Straighten</button>` : nothing}`;
  } else {
    const place = selected.kind === "place";
    const node = (place ? doc.places : doc.transitions).find((n) => n.id === selected.id);
    const set = (label, fn) => edit(label, (d) => fn((place ? d.places : d.transitions).find((n) => n.id === node.id)));
    body = html`${issuesOf(ctx, `${selected.kind}:${node.id}`)}
      ${text("Id", node.id, (v) => ctx.rename(selected.kind, node.id, v.trim()), { id: "f-node-id" })}
      ${text("Name", node.name, (v) => set("rename", (n) => { n.name = v || null; }), { id: "f-node-name" })}
      ${place ? html`
        ${text("Initial tokens", node.initial, (v) => set("change marking", (n) => { n.initial = Math.max(0, Math.round(v) || 0); }), { id: "f-place-initial", type: "number" })}
        ${check("Final place (the net ends here)", node.final, (v) => set("final", (n) => { n.final = v; }), "f-place-final")}
        ${node.final ? choice("Outcome", node.outcome, ctx.vocabulary?.final_outcomes ?? ["done", "failed"], (v) => set("outcome", (n) => { n.outcome = v; }), { id: "f-place-outcome", empty: null }) : nothing}
        ${actionForm(ctx, node)}`
      : html`
        ${text("Priority (higher fires first)", node.priority, (v) => set("change priority", (n) => { n.priority = Math.round(v) || 0; }), { id: "f-transition-priority", type: "number" })}
        ${conditionForm(ctx, node)}`}`;
  }
  return html`<form class="form" @submit=${(e) => e.preventDefault()}><fieldset ?disabled=${ctx.readOnly}><legend class="sr-only">Element</legend>${body}</fieldset></form>`;
}
