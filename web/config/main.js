// The site editor (/config, installers and admins): edit the draft on the plan, publish it
// live, history.
import { html, nothing, render } from "lit-html";
import { currentSession, currentToken, forgetToken, sessionHeaders } from "/lib/auth.js";
import { signInFlow } from "/lib/signin.js";
import { confirmAction } from "/lib/confirm.js";
import { clock, connectionBanner } from "/lib/dom.js";
import { HubClient } from "/lib/hub.js";
import { Api, ApiError } from "/lib/rest.js";
import { EditMap } from "/config/editmap.js";
import { KINDS, elementForm, newElement, round } from "/config/forms.js";
import { DraftModel } from "/config/model.js";
import { emergencyForm, toggleSafeSpot } from "/config/emergency.js";
import { mountTranslations, translationWarning } from "/config/translations.js";

const $ = (id) => document.getElementById(id);
let token = currentToken();
const api = new Api(() => token, () => (token ? {} : sessionHeaders()));
const EDITORS = new Set(["admin", "installer"]);

/** The signed-in person or token if it may edit the site, else an Error saying why not. */
async function editor() {
  const me = await api.get("/api/me").catch((err) => err);
  if (me instanceof Error) return me;
  if (!EDITORS.has(me.role)) {
    return new Error(`You are signed in as ${me.name} (role ${me.role}); the site editor is for installers and administrators.`);
  }
  return me;
}

/** A request whose body is a file (YAML, image): rest.js sends JSON only. */
async function sendFile(method, path, body, type) {
  let response;
  try {
    const auth = token ? { Authorization: `Bearer ${token}` } : sessionHeaders();
    response = await fetch(path, { method, body, headers: { ...auth, "Content-Type": type, Accept: "application/json" } });
  } catch {
    throw new ApiError(0, "The server cannot be reached: check the network.");
  }
  const data = await response.json().catch(() => ({}));
  if (!response.ok) {
    const detail = data.detail ?? null;
    const text = typeof detail === "string" ? detail : detail?.msg ?? `the server answered ${response.status}`;
    throw new ApiError(response.status, text, detail);
  }
  return data;
}

function showSignIn(message = "") {
  $("editor").hidden = true;
  const section = $("signin");
  section.hidden = false;
  signInFlow({
    section,
    intro: "The site editor is for installers and administrators.",
    tokenLabel: "Admin token",
    message,
    missing: "Enter your account name and password, or an admin token.",
    useToken: (value) => { token = value; },
    check: editor,
    done: start,
    again: showSignIn,
  });
}

async function boot() {
  if (!token && !(await currentSession())) return showSignIn();
  const me = await editor();
  if (me instanceof Error) {
    forgetToken();
    token = null;
    return showSignIn(me.message);
  }
  start(me);
}

async function start(me) {
  $("signin").hidden = true;
  $("editor").hidden = false;
  const model = new DraftModel(api);
  const hub = new HubClient({ token }).start();
  connectionBanner(hub, $("connection"));
  hub.subscribe("site_rollout");
  const ui = {
    me, model, api, hub, section: "pois", selected: null, tool: "select", oneWay: false,
    edgeFrom: null, calibration: null, notice: null, rollout: null, versions: [], diff: null,
    importErrors: null, floor: null, actions: 0,
  };
  window.guidebotEditor = ui; // for the browser tests and the benchmark
  hub.on("site_rollout", (m) => { ui.rollout = m.payload; draw(); });
  api.addEventListener("denied", (e) => { if (e.detail.status === 401) { forgetToken(); showSignIn(e.detail.message); } });
  model.addEventListener("failure", (e) => { ui.notice = { error: true, text: e.detail.message }; draw(); });
  const map = new EditMap($("map"), (url) => api.get(url));
  ui.map = map;
  model.addEventListener("change", () => draw());

  function select(section, index) {
    ui.section = section;
    ui.selected = index === null ? null : { section, index };
    draw();
  }
  const say = (text, error = false) => { ui.notice = { text, error }; draw(); };

  map.addEventListener("select", (e) => select(e.detail.section, e.detail.index));
  map.addEventListener("node", (e) => {
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
  map.addEventListener("mapclick", (e) => {
    const { x, y } = e.detail;
    if (ui.tool === "node") {
      const node = newElement(model.doc, "nodes", { x, y, floor: ui.floor });
      model.edit("add node", (d) => d.nodes.push(node));
      select("nodes", model.doc.nodes.length - 1);
      say(`Node ${node.id} added at (${node.x}, ${node.y}).`);
    } else if (ui.tool === "calibrate" && ui.calibration) {
      ui.calibration.points.push({ x, y });
      draw();
    }
  });
  map.addEventListener("nodemove", (e) => {
    model.edit("move node", (d) => { d.nodes[e.detail.index].x = round(e.detail.x); d.nodes[e.detail.index].y = round(e.detail.y); });
  });
  map.addEventListener("poidrop", (e) => {
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

  async function loadVersions() {
    ui.versions = await api.get("/api/site/versions");
  }

  async function upload(kind, input, done) {
    const file = input.files?.[0];
    if (!file) return;
    try {
      const reply = await sendFile("POST", `/api/site/uploads/${kind}`, file, file.type || "application/octet-stream");
      done(reply.path);
      say(`${file.name} uploaded.`);
    } catch (err) {
      say(`Upload refused: ${err.message}`, true);
    }
    input.value = "";
  }

  async function regenerate(name) {
    await model.saving;
    try {
      const reply = await api.post(`/api/site/draft/robots/${encodeURIComponent(name)}/token`, { revision: model.revision });
      await model.load();
      ui.token = { robot: name, token: reply.token };
      draw();
    } catch (err) {
      say(err.message, true);
    }
  }

  function remove(section, index) {
    model.edit(`delete ${KINDS[section].one}`, (d) => d[section].splice(index, 1));
    select(section, null);
  }

  async function publish() {
    try {
      const note = $("publish-note")?.value ?? "";
      const untranslated = await translationWarning(api, model);
      const version = await model.publish(note);
      ui.rollout = ui.rollout?.version === version ? ui.rollout : { version, expected: [], loaded_ms: {}, complete: false };
      await loadVersions();
      say(`Version ${version} is live.${untranslated}`);
    } catch (err) {
      if (err instanceof ApiError && err.status === 422) say(`Publish refused: ${err.detail.length} problem(s), see the list.`, true);
      else say(`Publish refused: ${err.detail?.msg ?? err.message}`, true);
    }
  }

  async function rollback(version) {
    const ok = await confirmAction({
      title: `Roll back to version ${version}?`,
      text: `Version ${version} goes live again (as a new version) on the server and every robot at once; the changes made since are no longer live (they stay in the history).`,
      confirm: `Roll back to version ${version}`,
      keep: "Keep the live version",
    });
    if (!ok) return;
    try {
      const reply = await api.post("/api/site/rollback", { version });
      await model.load();
      await loadVersions();
      say(`Rolled back: version ${version} is live again as version ${reply.version}.`);
    } catch (err) {
      say(err.message, true);
    }
  }

  async function showDiff(from, to, title) {
    ui.diff = { title, changes: await api.get(`/api/site/diff?from=${from}&to=${to}`) };
    draw();
  }

  async function exportYaml() {
    try {
      const blob = await api.get("/api/site/draft/export");
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = "site.yaml";
      a.click();
    } catch (err) {
      say(`Export refused: ${err.message}`, true);
    }
  }

  async function importYaml(input) {
    const file = input.files?.[0];
    if (!file) return;
    await model.saving;
    try {
      await sendFile("POST", `/api/site/draft/import?revision=${model.revision}`, await file.text(), "application/yaml");
      ui.importErrors = null;
      await model.load();
      say(`${file.name} imported into the draft.`);
    } catch (err) {
      ui.importErrors = Array.isArray(err.detail) ? err.detail : [{ loc: "(document)", msg: err.message, line: null }];
      say(`${file.name} refused: ${ui.importErrors.length} problem(s).`, true);
    }
    input.value = "";
  }

  function applyCalibration(event) {
    event.preventDefault();
    const form = new FormData(event.target);
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

  document.addEventListener("keydown", (e) => {
    if (e.target.closest?.("input, textarea, select")) return;
    if ((e.ctrlKey || e.metaKey) && e.key === "z") { e.preventDefault(); model.undo(); }
    if ((e.ctrlKey || e.metaKey) && (e.key === "y" || (e.shiftKey && e.key === "Z"))) { e.preventDefault(); model.redo(); }
  });

  const ctxFor = (section, index) => ({
    doc: model.doc, section, index,
    issues: model.issuesByElement().get(`${section}/${index}`) ?? [],
    edit: (label, fn) => model.edit(label, fn),
    upload, regenerate, remove,
    calibrate: (i) => { ui.tool = "calibrate"; ui.calibration = { index: i, points: [] }; ui.floor = model.doc.floors[i].id; draw(); },
  });

  function draw() {
    if (!model.doc) return;
    const doc = model.doc;
    if (!doc.floors.some((f) => f.id === ui.floor)) ui.floor = doc.floors[0]?.id;
    const byElement = model.issuesByElement();
    if (ui.selected && !doc[ui.selected.section]?.[ui.selected.index]) ui.selected = null;
    map.draw(doc, ui.floor, byElement, ui.selected);
    const count = model.issues.length;
    const em = doc.emergency;
    const emIssues = model.issues.filter((i) => i.loc.startsWith("emergency")).length;
    const zonesHere = (em?.alarms ?? []).filter((a) => !a.zone?.areas?.length && (!a.zone?.floors?.length || a.zone.floors.includes(ui.floor)));
    render(html`
      <span>${me.name} <span class="badge">${me.role}</span></span>
      <span class="muted" id="draft-status">Draft revision ${model.revision} · live version ${model.liveVersion}</span>
      <button type="button" class="secondary" ?disabled=${!model.undoStack.length} @click=${() => model.undo()}
        title=${model.undoStack.length ? `Undo ${model.undoStack.at(-1).label}` : "Nothing to undo"}>Undo</button>
      <button type="button" class="secondary" ?disabled=${!model.redoStack.length} @click=${() => model.redo()}>Redo</button>
      <label>Note <input id="publish-note" placeholder="what changed" maxlength="500"></label>
      <button type="button" id="publish" ?disabled=${!!model.conflict} @click=${publish}
        aria-describedby="problem-count">Publish</button>
      <span id="problem-count" class=${count ? "error" : "ok-text"}>${count ? `${count} problem(s): publishing is refused` : "No problems"}</span>`, $("bar"));
    render(html`
      ${model.conflict ? html`<div class="notice error" role="alert"><strong>Your last change was not saved.</strong> ${model.conflict.message}
        <button type="button" @click=${() => model.reload()}>Reload the draft (drop my changes)</button>
        <button type="button" class="secondary" @click=${() => model.merge()}>Merge my changes into it</button></div>` : nothing}
      ${ui.notice ? html`<div class=${`notice ${ui.notice.error ? "error" : "ok"}`} role=${ui.notice.error ? "alert" : "status"}>${ui.notice.text}</div>` : nothing}
      ${ui.token ? html`<div class="notice ok" role="status">New token for robot ${ui.token.robot} (shown once: copy it now, then publish):
        <output class="token">${ui.token.token}</output> <button type="button" class="secondary" @click=${() => { ui.token = null; draw(); }}>Done</button></div>` : nothing}`, $("notices"));
    render(html`
      <nav aria-label="Element kinds"><ul class="kinds">${Object.entries(KINDS).map(([section, kind]) => {
        const bad = [...byElement.keys()].filter((k) => k.startsWith(`${section}/`)).length;
        return html`<li><button type="button" class=${ui.section === section ? "kind current" : "kind secondary"} aria-pressed=${ui.section === section ? "true" : "false"}
          @click=${() => select(section, null)}>${kind.label} (${(doc[section] ?? []).length})${bad ? html` <span class="error">⚠ ${bad}</span>` : nothing}</button></li>`;
      })}<li><button type="button" class=${ui.section === "emergency" ? "kind current" : "kind secondary"} aria-pressed=${ui.section === "emergency" ? "true" : "false"}
          @click=${() => select("emergency", null)}>Fire alarm (${em ? `${em.alarms.length} input(s)` : "none"})${emIssues ? html` <span class="error">⚠ ${emIssues}</span>` : nothing}</button></li></ul></nav>
      ${ui.section === "emergency" ? html`<h2 id="list-title">Fire alarm</h2>
      <p class="muted">${em ? `${em.alarms.length} alarm input(s), ${em.safe_spots.length} safe spot(s), ${em.escape_routes.length} escape route(s): edit them on the right, safe spots also on the plan.` : "Not set up yet."}</p>` : html`
      <h2 id="list-title">${KINDS[ui.section].label}</h2>
      <ul class="elements" aria-labelledby="list-title">${(doc[ui.section] ?? []).map((item, i) => {
        const label = ui.section === "edges" ? `${item.a} ${item.one_way ? "→" : "↔"} ${item.b}` : `${item.name && item.id ? `${item.name} (${item.id})` : item.name || item.id}`;
        const bad = byElement.has(`${ui.section}/${i}`);
        return html`<li><button type="button" class=${`element${bad ? " has-issue" : ""}${ui.selected?.index === i ? " current" : ""}`}
          aria-current=${ui.selected?.index === i ? "true" : "false"} @click=${() => select(ui.section, i)}>${label}${bad ? " ⚠" : ""}</button></li>`;
      })}</ul>
      <button type="button" @click=${() => {
        const item = newElement(doc, ui.section, { x: 0, y: 0, floor: ui.floor });
        model.edit(`add ${KINDS[ui.section].one}`, (d) => { d[ui.section] ??= []; d[ui.section].push(item); });
        select(ui.section, model.doc[ui.section].length - 1);
      }}>Add ${KINDS[ui.section].one}</button>`}`, $("lists"));
    render(html`
      <label for="floor-select">Floor</label> <select id="floor-select" @change=${(e) => { ui.floor = e.target.value; draw(); }}>
        ${doc.floors.map((f) => html`<option value=${f.id} ?selected=${f.id === ui.floor}>${f.name || f.id}</option>`)}</select>
      <fieldset class="tools"><legend class="sr-only">Tool</legend>
        ${[["select", "Select"], ["node", "Add node"], ["edge", "Add edge"], ["safe", "Safe spot"]].map(([t, label]) => html`
          <label class="tool"><input type="radio" name="tool" value=${t} .checked=${ui.tool === t}
            @change=${() => { ui.tool = t; ui.edgeFrom = null; draw(); }}> ${label}</label>`)}
        <label class="tool"><input type="checkbox" .checked=${ui.oneWay} @change=${(e) => { ui.oneWay = e.target.checked; }}> one-way</label>
      </fieldset>
      ${zonesHere.length ? html`<span class="alarm-zone" id="alarm-zones">Alarm inputs covering this floor (configuration, not a live alarm): ${zonesHere.map((a) => `${a.id} (${a.zone?.floors?.length ? "floor" : "whole site"})`).join(", ")}</span>` : nothing}
      ${ui.calibration ? html`<form class="calibrate" @submit=${applyCalibration} aria-label="Calibrate the plan">
        <span>Calibrate: click two points on the plan a known distance apart (${ui.calibration.points.length} of 2).</span>
        ${ui.calibration.points.length >= 2 ? html`
          <label>Distance (m) <input name="distance" type="number" step="any" min="0" required></label>
          <label>First point x (m) <input name="x" type="number" step="any" value="0"></label>
          <label>y (m) <input name="y" type="number" step="any" value="0"></label>
          <button type="submit">Apply calibration</button>` : nothing}
        <button type="button" class="secondary" @click=${() => { ui.calibration = null; ui.tool = "select"; draw(); }}>Cancel</button></form>` : nothing}`, $("map-toolbar"));
    render(html`
      <section aria-labelledby="details-title"><h2 id="details-title" class="sr-only">Selected element</h2>
        ${ui.section === "emergency" ? emergencyForm({ doc, issues: model.issues, edit: (label, fn) => model.edit(label, fn) })
          : ui.selected ? elementForm(ctxFor(ui.selected.section, ui.selected.index)) : html`<p class="muted">Select an element on the plan or in the list.</p>`}</section>
      <section aria-labelledby="problems-title"><h2 id="problems-title">Problems (${model.issues.length})</h2>
        ${model.issues.length ? html`<ul class="problems">${model.issues.map((issue) => {
          const m = /^([a-z_]+)\[(\d+)\]/.exec(issue.loc);
          const go = () => (issue.loc.startsWith("emergency") ? select("emergency", null) : m && select(m[1], Number(m[2])));
          return html`<li><button type="button" class="link" @click=${go}>${model.describeLoc(issue.loc)}</button>: ${issue.msg}</li>`;
        })}</ul>` : html`<p class="ok-text">The draft passes every check of <code>guidebot site check</code>.</p>`}</section>
      <section aria-labelledby="publish-title"><h2 id="publish-title">Published versions</h2>
        ${ui.rollout ? html`<p role="status" id="rollout">${rolloutText(ui.rollout)}</p>` : nothing}
        <button type="button" class="secondary" @click=${() => showDiff(model.liveVersion, "draft", "Draft compared with the live version")}>Changes in the draft</button>
        <table><caption class="sr-only">Published versions</caption><thead><tr><th>Version</th><th>By</th><th>When</th><th>Actions</th></tr></thead>
        <tbody>${ui.versions.map((v, i) => html`<tr><td>${v.version}${v.version === model.liveVersion ? " (live)" : ""}</td>
          <td>${v.published_by || "—"}</td><td>${clock(v.published_at)}${v.note ? html`<br><span class="muted">${v.note}</span>` : nothing}</td>
          <td>${ui.versions[i + 1] ? html`<button type="button" class="secondary small" aria-label=${`Changes in version ${v.version}`} @click=${() => showDiff(ui.versions[i + 1].version, v.version, `Changes in version ${v.version}`)}>Changes</button>` : nothing}
          ${v.version !== model.liveVersion ? html`<button type="button" class="secondary small" aria-label=${`Roll back to version ${v.version}`} @click=${() => rollback(v.version)}>Roll back</button>` : nothing}</td></tr>`)}</tbody></table>
        ${ui.diff ? html`<h3>${ui.diff.title}</h3><ul class="diff" aria-label=${ui.diff.title}>${ui.diff.changes.length ? ui.diff.changes.map((c) => html`<li class=${`diff-${c.change}`}>${c.text}</li>`) : html`<li>No changes.</li>`}</ul>` : nothing}</section>
      <section aria-labelledby="yaml-title"><h2 id="yaml-title">Site file (YAML)</h2>
        <button type="button" class="secondary" @click=${exportYaml}>Export draft as YAML</button>
        <label>Import YAML into the draft <input type="file" accept=".yaml,.yml,application/yaml,text/yaml" @change=${(e) => importYaml(e.target)}></label>
        ${ui.importErrors ? html`<ul class="problems" aria-label="Problems in the imported file">${ui.importErrors.map((i) => html`<li>line ${i.line ?? "?"}: ${i.loc}: ${i.msg}</li>`)}</ul>` : nothing}</section>`, $("details"));
  }

  // Load last, once every handler above exists: the page draws as soon as the draft arrives, and a
  // control used before the version list is in must not reach a helper that is not declared yet.
  await model.load();
  ui.floor = model.doc.floors[0].id;
  await loadVersions();
  draw();
  mountTranslations({ model, api, sendFile, root: $("translations"), nav: $("views"), columns: $("columns") });
}

function rolloutText(r) {
  const n = r.expected.length;
  const done = Object.keys(r.loaded_ms).length;
  if (!n) return `Version ${r.version} is live (no robot connected).`;
  if (r.complete) return `Version ${r.version} reached all ${n} robot(s) in ${Math.round(r.ms)} ms.`;
  return `Version ${r.version}: ${done} of ${n} robot(s) updated…`;
}

boot();
