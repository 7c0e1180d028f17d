// The site's fire alarm part (docs/emergency.md) in the editor: alarm inputs and their zones,
// safe spots, escape routes and the words per language. Unlike the other kinds it is one
// object, not a list: this form edits `doc.emergency` as a whole, and the plan draws its safe
// spots and escape routes (editmap.js).
import { html, nothing } from "lit-html";

/** An empty emergency part: one alarm for the whole site on the first input point found. */
export function newEmergency(doc) {
  const input = (doc.modules ?? []).flatMap((m) => (m.points ?? []).map((p) => ({ module: m.id, point: p.name })))[0]
    ?? { module: "", point: "" };
  const lang = doc.default_language || "en";
  return {
    alarms: [{ id: "fire_alarm", input, active_when: 1, zone: {} }],
    safe_spots: [],
    escape_routes: [],
    words: { [lang]: "Fire alarm. Please follow the exit signs. I will wait out of the way." },
  };
}

/** The kind of zone of an alarm: "site", "floors" or "areas". */
const zoneKind = (zone) => (zone?.floors?.length ? "floors" : zone?.areas?.length ? "areas" : "site");

/**
 * The form. `ctx`: {doc, issues (the draft's problems), edit(label, fn)}; fn gets the draft.
 */
export function emergencyForm(ctx) {
  const { doc } = ctx;
  const em = doc.emergency;
  const edit = (label, fn) => ctx.edit(label, (d) => fn(d.emergency));
  const issues = ctx.issues.filter((i) => i.loc.startsWith("emergency"));
  const issuesAt = (prefix) => issues.filter((i) => i.loc === prefix || i.loc.startsWith(`${prefix}.`) || i.loc.startsWith(`${prefix}[`));
  const note = (prefix, id) => {
    const bad = issuesAt(prefix);
    return bad.length ? html`<span class="field-issue" id=${id}>${bad.map((b) => b.msg).join("; ")}</span>` : nothing;
  };
  if (!em) {
    return html`<section class="element-form" aria-labelledby="em-title"><h3 id="em-title">Fire alarm</h3>
      <p>This site says nothing about a fire alarm: robots would not know where to wait, nor which corridors to leave.</p>
      <button type="button" @click=${() => ctx.edit("add the fire alarm part", (d) => { d.emergency = newEmergency(d); })}>Add the fire alarm part</button></section>`;
  }
  const points = (doc.modules ?? []).flatMap((m) => (m.points ?? []).map((p) => ({ module: m.id, point: p.name, kind: p.kind })));
  const floorOf = new Map(doc.nodes.map((n) => [n.id, n.floor]));
  const languages = [...new Set([doc.default_language || "en", ...(doc.languages ?? []), ...Object.keys(em.words ?? {})])];
  const alarm = (a, i) => {
    const kind = zoneKind(a.zone);
    const id = `em-alarm-${i}`;
    const inputValue = `${a.input?.module}/${a.input?.point}`;
    const inputBad = issuesAt(`emergency.alarms[${i}].input`).length > 0;
    const choices = kind === "floors" ? doc.floors.map((f) => [f.id, f.name || f.id]) : (doc.areas ?? []).map((ar) => [ar.id, ar.id]);
    return html`<fieldset class="field alarm" aria-label=${`Alarm ${a.id}`}><legend>Alarm ${a.id}</legend>
      <div class="field"><label for=${`${id}-id`}>id</label>
        <input id=${`${id}-id`} .value=${a.id} @change=${(e) => edit("alarm id", (m) => { m.alarms[i].id = e.target.value.trim(); })}>${note(`emergency.alarms[${i}].id`)}</div>
      <div class="field"><label for=${`${id}-input`}>input</label>
        <select id=${`${id}-input`} aria-invalid=${inputBad ? "true" : "false"} aria-describedby=${inputBad ? `${id}-input-issue` : nothing}
          @change=${(e) => edit("alarm input", (m) => { const [module, point] = e.target.value.split("/"); m.alarms[i].input = { module, point }; })}>
          ${points.some((p) => `${p.module}/${p.point}` === inputValue) ? nothing : html`<option value=${inputValue} selected>${inputValue} (not a point of the site)</option>`}
          ${points.map((p) => html`<option value=${`${p.module}/${p.point}`} ?selected=${`${p.module}/${p.point}` === inputValue}>${p.module}/${p.point} (${p.kind})</option>`)}
        </select>${note(`emergency.alarms[${i}].input`, `${id}-input-issue`)}</div>
      <div class="field"><label for=${`${id}-active`}>alarm when the input reads</label>
        <select id=${`${id}-active`} @change=${(e) => edit("alarm contact", (m) => { m.alarms[i].active_when = Number(e.target.value); })}>
          <option value="1" ?selected=${(a.active_when ?? 1) === 1}>1 (normally-open contact)</option>
          <option value="0" ?selected=${a.active_when === 0}>0 (normally-closed contact: a cut wire alarms)</option>
        </select></div>
      <div class="field"><label for=${`${id}-zone`}>zone</label>
        <select id=${`${id}-zone`} @change=${(e) => edit("alarm zone", (m) => {
          const k = e.target.value;
          m.alarms[i].zone = k === "floors" ? { floors: [doc.floors[0]?.id].filter(Boolean) } : k === "areas" ? { areas: [(doc.areas ?? [])[0]?.id].filter(Boolean) } : {};
        })}>
          <option value="site" ?selected=${kind === "site"}>the whole site</option>
          <option value="floors" ?selected=${kind === "floors"}>floors</option>
          <option value="areas" ?selected=${kind === "areas"}>restricted areas</option>
        </select>${note(`emergency.alarms[${i}].zone`)}</div>
      ${kind === "site" ? nothing : html`<fieldset class="field"><legend>${kind === "floors" ? "Floors of the zone" : "Areas of the zone"}</legend>
        ${choices.map(([value, label]) => html`<label><input type="checkbox" .checked=${(a.zone[kind] ?? []).includes(value)}
          @change=${(e) => edit("alarm zone", (m) => {
            const list = new Set(m.alarms[i].zone[kind] ?? []);
            if (e.target.checked) list.add(value); else list.delete(value);
            m.alarms[i].zone = list.size ? { [kind]: [...list] } : {};
          })}> ${label}</label>`)}</fieldset>`}
      <button type="button" class="danger small" @click=${() => edit("remove alarm", (m) => m.alarms.splice(i, 1))}>Remove alarm ${a.id}</button>
    </fieldset>`;
  };
  const addAlarm = () => edit("add alarm", (m) => {
    const used = new Set(m.alarms.map((a) => a.id));
    let n = m.alarms.length + 1;
    while (used.has(`fire_alarm_${n}`)) n += 1;
    m.alarms.push({ ...newEmergency(doc).alarms[0], id: `fire_alarm_${n}` });
  });
  const addSpot = (e) => {
    const select = e.target.closest(".field").querySelector("select");
    if (select.value && !em.safe_spots.includes(select.value)) edit("add safe spot", (m) => m.safe_spots.push(select.value));
  };
  return html`<section class="element-form emergency" aria-labelledby="em-title"><h3 id="em-title">Fire alarm</h3>
    <p class="muted">What robots do when the building's fire alarm sounds: stop, say the words, leave the escape routes and wait at a safe spot (docs/emergency.md).</p>
    ${issues.length ? html`<div class="notice error" role="alert">${issues.map((i) => html`<div>${i.loc}: ${i.msg}</div>`)}</div>` : nothing}
    <h4>Alarm inputs</h4>
    ${em.alarms.map(alarm)}
    <button type="button" @click=${addAlarm}>Add alarm input</button>
    <h4 id="em-spots">Safe spots</h4>
    <p class="muted">Nodes where a robot waits out an alarm, out of everyone's way. With the “Safe spot” tool, click a node on the plan to add or remove it.</p>
    <ul class="plain" aria-labelledby="em-spots">${em.safe_spots.map((s, i) => html`<li>${s} <span class="muted">(${floorOf.get(s) ?? "no such node"})</span>
      <button type="button" class="secondary small" aria-label=${`Remove safe spot ${s}`} @click=${() => edit("remove safe spot", (m) => m.safe_spots.splice(i, 1))}>✕</button>
      ${note(`emergency.safe_spots[${i}]`)}</li>`)}</ul>
    <div class="field"><label for="em-spot-add">Node to add</label>
      <select id="em-spot-add">${doc.nodes.filter((n) => !em.safe_spots.includes(n.id)).map((n) => html`<option value=${n.id}>${n.id} (${n.floor})</option>`)}</select>
      <button type="button" @click=${addSpot}>Add safe spot</button></div>
    <fieldset class="field"><legend>Escape routes (restricted areas robots leave at once and do not enter)</legend>
      ${(doc.areas ?? []).length ? (doc.areas ?? []).map((a) => html`<label><input type="checkbox" .checked=${em.escape_routes.includes(a.id)}
        @change=${(e) => edit("escape route", (m) => {
          m.escape_routes = e.target.checked ? [...new Set([...m.escape_routes, a.id])] : m.escape_routes.filter((r) => r !== a.id);
        })}> ${a.id}</label>`) : html`<span class="muted">No restricted area yet: draw the corridors as restricted areas first.</span>`}
      ${note("emergency.escape_routes")}</fieldset>
    <fieldset class="field"><legend>Words robots say and pages show, per language</legend>
      ${languages.map((lang) => html`<label class="block">${lang}${lang === (doc.default_language || "en") ? " (default)" : ""}
        <textarea rows="2" .value=${em.words?.[lang] ?? ""} @change=${(e) => edit("alarm words", (m) => {
          const text = e.target.value.trim();
          m.words = { ...(m.words ?? {}) };
          if (text) m.words[lang] = text; else delete m.words[lang];
        })}></textarea></label>`)}
      ${note("emergency.words")}</fieldset>
    <button type="button" class="danger" @click=${() => ctx.edit("remove the fire alarm part", (d) => { delete d.emergency; })}>Remove the fire alarm part</button>
  </section>`;
}

/** Toggle `node` as a safe spot (the plan's "Safe spot" tool). */
export function toggleSafeSpot(model, node) {
  const on = model.doc.emergency?.safe_spots?.includes(node);
  return model.edit(on ? "remove safe spot" : "add safe spot", (d) => {
    d.emergency ??= newEmergency(d);
    d.emergency.safe_spots = on ? d.emergency.safe_spots.filter((s) => s !== node) : [...d.emergency.safe_spots, node];
  });
}
