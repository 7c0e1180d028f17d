// The RoboGraph editor (/nets/, docs/nets.md): open a library net or a PNML file, draw and edit
// it, checked by the engine's rules as you edit, export it as PNML, publish it to the fleet.
// Who may publish (the server's edit_nets rule) edits; other staff read.
import { html, nothing, render } from "lit-html";
import { ApiError } from "/lib/rest.js";
import { StaffSession } from "/lib/session.js";
import { NetCanvas } from "/nets/canvas.js";
import { detailsForm } from "/nets/forms.js";
import { Attachment, attachPanel } from "/nets/attach.js";
import { libraryPanel } from "/nets/library.js";
import { NetModel, emptyNet } from "/nets/model.js";
import { confirmAction } from "/lib/confirm.js";
import { Run, defaultParams, parseReplies, simulationPanel } from "/nets/simulation.js";

const $ = (id) => document.getElementById(id);

/** The signed-in person's or token's name and role, and the editor's vocabulary (which says
 * whether it may publish); an Error when unknown or not staff's (the read_nets rule). */
async function whoAndWhat(api) {
  const me = await api.get("/api/me").catch((err) => err);
  if (me instanceof Error) return me;
  const vocabulary = await api.get("/api/net-editor/vocabulary").catch((err) => err);
  if (vocabulary instanceof ApiError && vocabulary.status === 403) return new Error(`You are signed in as ${me.name} (role ${me.role}); the net editor is for staff.`);
  if (vocabulary instanceof Error) return vocabulary;
  return { me, vocabulary };
}

const session = new StaffSession({
  section: $("signin"),
  intro: "Those who may publish nets edit them; other staff read them.",
  missing: "Enter your account name and password, or a staff token.",
  check: whoAndWhat,
  hide: () => { $("editor").hidden = true; },
  start,
});
const { api } = session;
/** A PNML file to the server: the REST client sends JSON only. */
const sendFile = (path, body) => session.sendFile("POST", path, body, "application/xml");

async function start({ me, vocabulary }) {
  $("editor").hidden = false;
  const readOnly = !vocabulary.may_publish;
  const model = new NetModel(api);
  // Leaving the page drops edits that are nowhere else: the browser asks first.
  addEventListener("beforeunload", (e) => { if (!readOnly && model.unpublished) e.preventDefault(); });
  const ui = { me, model, readOnly, tool: "select", selected: null, notice: null, library: [], vocabulary, libraryNet: "",
    group: new Set(), clipboard: null, run: null, playing: null, simParams: "{}", simReplies: "", analysis: null,
    versions: null, diff: null, mayDebug: vocabulary.may_publish, stepwise: null };
  window.guidebotNets = ui; // for the browser tests
  ui.draw = () => draw();
  const say = (text, error = false) => { ui.notice = { text, error }; draw(); };
  const select = (kind, id) => {
    ui.selected = kind ? { kind, id } : null;
    ui.group = new Set(kind === "place" || kind === "transition" ? [id] : []);
    draw();
  };
  /** Shift+click: a node joins (or leaves) the selection; moved, copied and deleted together. */
  const toggle = (kind, id) => {
    if (ui.group.has(id)) ui.group.delete(id);
    else { ui.group.add(id); ui.selected = { kind, id }; }
    if (ui.selected?.id === id && !ui.group.has(id)) ui.selected = null;
    draw();
  };

  const canvas = new NetCanvas($("canvas"), {
    select,
    toggle,
    /** A rubber band: the nodes inside it become the selection (moved, copied, deleted together). */
    selectMany(ids) {
      ui.group = new Set(ids);
      ui.selected = null;
      say(ids.length ? `${ids.length} node(s) selected: ${ids.join(", ")}.` : "No node inside the band.");
    },
    add(tool, x, y) {
      const kind = tool === "place" ? "place" : "transition";
      const id = model.freshId(kind === "place" ? "p" : "t");
      model.edit(`add ${kind}`, (d) => {
        if (kind === "place") d.places.push({ id, name: id, x, y, initial: 0, final: false, outcome: "done", action: null });
        else d.transitions.push({ id, name: id, x, y, priority: 0, condition: null });
      });
      select(kind, id);
      say(`${kind === "place" ? "Place" : "Transition"} ${id} added.`);
    },
    move(ids, dx, dy) {
      model.edit(ids.length > 1 ? `move ${ids.length} nodes` : "move", () => {
        for (const id of ids) { const n = model.node(id); n.x += dx; n.y += dy; }
      });
    },
    /** Change an arc's bend points (`fn` edits the list in place). */
    bend(arcId, fn) {
      model.edit("bend arc", (d) => {
        const arc = d.arcs.find((x) => x.id === arcId);
        arc.points ??= [];
        fn(arc.points);
      });
      select("arc", arcId);
    },
    connect(a, b) {
      const isPlace = (id) => model.doc.places.some((p) => p.id === id);
      if (isPlace(a) === isPlace(b)) return say("An arc joins a place and a transition.", true);
      const existing = model.doc.arcs.find((arc) => arc.source === a && arc.target === b);
      if (existing) return say(`There is already an arc ${a} → ${b}: change its weight instead.`, true);
      const id = model.freshId("a");
      model.edit("add arc", (d) => d.arcs.push({ id, source: a, target: b, weight: 1, points: [] }));
      select("arc", id);
      say(`Arc ${a} → ${b} added.`);
    },
  });

  function remove(kind, id) {
    const ids = kind !== "arc" && ui.group.has(id) ? new Set(ui.group) : new Set([id]);
    model.edit(ids.size > 1 ? `delete ${ids.size} nodes` : `delete ${kind}`, (d) => {
      if (kind === "arc") d.arcs = d.arcs.filter((a) => a.id !== id);
      else {
        d.places = d.places.filter((p) => !ids.has(p.id));
        d.transitions = d.transitions.filter((t) => !ids.has(t.id));
        d.arcs = d.arcs.filter((a) => !ids.has(a.source) && !ids.has(a.target));
      }
    });
    select(null);
  }

  /** The selected nodes and the arcs between them, kept for Paste. */
  function copy() {
    const ids = ui.group;
    if (!ids.size) return say("Select one or more places or transitions to copy (Shift+click adds one).", true);
    const doc = model.doc;
    ui.clipboard = structuredClone({
      places: doc.places.filter((p) => ids.has(p.id)),
      transitions: doc.transitions.filter((t) => ids.has(t.id)),
      arcs: doc.arcs.filter((a) => ids.has(a.source) && ids.has(a.target)),
    });
    say(`${ids.size} node(s) copied.`);
  }

  /** The copied nodes again, shifted, with new ids (their arcs follow). */
  function paste() {
    const clip = ui.clipboard;
    if (!clip) return say("Nothing copied yet.", true);
    const pasted = [];
    model.edit("paste", (d) => {
      const renamed = new Map();
      const fresh = (id) => {
        const base = id.replace(/_?\d+$/, "") || "n";
        renamed.set(id, model.freshId(`${base}_`));
        return renamed.get(id);
      };
      for (const p of clip.places) { const id = fresh(p.id); d.places.push({ ...structuredClone(p), id, x: p.x + 40, y: p.y + 40 }); pasted.push(id); }
      for (const t of clip.transitions) { const id = fresh(t.id); d.transitions.push({ ...structuredClone(t), id, x: t.x + 40, y: t.y + 40 }); pasted.push(id); }
      for (const a of clip.arcs) d.arcs.push({ ...a, id: model.freshId("a"), source: renamed.get(a.source), target: renamed.get(a.target),
        points: (a.points ?? []).map(([x, y]) => [x + 40, y + 40]) });
    });
    ui.group = new Set(pasted);
    ui.selected = null;
    say(`${pasted.length} node(s) pasted: ${pasted.join(", ")}.`);
  }

  /** Give a node a new id: its arcs follow. */
  function rename(kind, id, next) {
    if (!next || next === id) return;
    if (model.node(next) || model.doc.arcs.some((a) => a.id === next)) return say(`The id ${next} is taken.`, true);
    model.edit(`rename ${kind}`, (d) => {
      if (kind === "arc") { d.arcs.find((a) => a.id === id).id = next; return; }
      const list = kind === "place" ? d.places : d.transitions;
      list.find((n) => n.id === id).id = next;
      for (const a of d.arcs) { if (a.source === id) a.source = next; if (a.target === id) a.target = next; }
    });
    select(kind, next);
  }

  /** A net opened: its parameters' defaults fill the simulation form. */
  function opened() {
    canvas.fit(model.doc);
    stopSimulating();
    ui.simParams = defaultParams(model.doc);
    select(null);
  }

  function stopSimulating() {
    if (ui.playing) clearInterval(ui.playing);
    ui.playing = null;
    ui.run = null;
  }

  /** One run with the replies chosen so far: drawn at its last step. */
  async function runChosen() {
    const { params, chosen } = ui.stepwise;
    try {
      ui.run = new Run(await api.post("/api/net-editor/simulate", { net: model.doc, params, chosen }));
      ui.run.at = ui.run.steps.length - 1;
      const outcome = ui.run.result.outcome;
      say(outcome === "waiting" ? `${chosen.length} repl${chosen.length === 1 ? "y" : "ies"} chosen: the net waits for the next.` : `Simulated with the replies chosen: outcome ${outcome}.`);
    } catch (err) {
      say(`Simulation refused: ${err.message}`, true);
    }
  }

  const simulation = {
    async start(form) {
      stopSimulating();
      ui.simParams = form.get("params");
      ui.simReplies = form.get("replies");
      let params;
      let replies;
      try {
        params = JSON.parse(ui.simParams || "{}");
        replies = parseReplies(ui.simReplies);
      } catch (err) {
        return say(`Simulation refused: ${err.message}`, true);
      }
      if (form.get("stepwise")) {
        ui.stepwise = { params, chosen: [] };
        return runChosen();
      }
      ui.stepwise = null;
      try {
        ui.run = new Run(await api.post("/api/net-editor/simulate", { net: model.doc, params, replies }));
        say(`Simulated: ${ui.run.steps.length - 1} step(s), outcome ${ui.run.result.outcome}. Step through it.`);
      } catch (err) {
        say(`Simulation refused: ${err.message}`, true);
      }
    },
    choose(reply) {
      ui.stepwise.chosen.push(reply);
      return runChosen();
    },
    step() { if (!ui.run.done) ui.run.at += 1; draw(); },
    reset() { ui.run.at = 0; draw(); },
    end() { ui.run.at = ui.run.steps.length - 1; draw(); },
    play() {
      ui.playing = setInterval(() => {
        if (!ui.run || ui.run.done) { simulation.pause(); return; }
        ui.run.at += 1;
        draw();
      }, 500);
      draw();
    },
    pause() { clearInterval(ui.playing); ui.playing = null; draw(); },
    close() { stopSimulating(); draw(); },
    download() {
      const a = document.createElement("a");
      a.href = URL.createObjectURL(new Blob([ui.run.traceFile()], { type: "application/x-ndjson" }));
      a.download = `${model.doc.id}.trace.jsonl`;
      a.click();
    },
  };

  /** Opening another net drops the open one's edits that are nowhere else: ask first. */
  async function mayDrop(what) {
    if (readOnly || !model.unpublished) return true;
    const name = model.doc.id;
    return confirmAction({
      title: `Drop your changes to ${name}?`,
      text: `${name} has changes that are not published: ${what} drops them (export it as PNML to keep a copy).`,
      confirm: "Drop my changes",
      keep: `Keep editing ${name}`,
    });
  }

  async function openLibrary(name, ask = true) {
    if (ask && !(await mayDrop(`opening ${name}`))) return;
    try {
      model.open(await api.get(`/api/net-editor/library/${encodeURIComponent(name)}`));
      opened();
      say(`Net ${name} opened from the library.`);
      await loadVersions(name);
    } catch (err) {
      say(err.message, true);
    }
  }

  /** The open net's published versions (none: a net the library does not have yet). */
  async function loadVersions(name) {
    ui.diff = null;
    try {
      ui.versions = await api.get(`/api/net-editor/versions/${encodeURIComponent(name)}`);
    } catch (err) {
      if (!(err instanceof ApiError && err.status === 404)) say(err.message, true);
      ui.versions = null;
    }
    draw();
  }

  const attachment = new Attachment(api, session.token, () => draw());
  ui.attachment = attachment;
  const attaching = {
    async list() {
      try { await attachment.list(); } catch (err) { say(err.message, true); }
    },
    async attach(item) {
      try {
        if (model.doc?.id !== item.net) {
          model.open(await api.get(`/api/net-editor/library/${encodeURIComponent(item.net)}`));
          opened();
          await loadVersions(item.net);
        }
        ui.libraryNet = item.net;
        stopSimulating();
        await attachment.attach(item);
        say(`Attached to ${item.instance_id} on ${attachment.target}: its live marking is drawn.`);
      } catch (err) {
        say(err.message, true);
      }
    },
    async toggle(transition) {
      try { await attachment.toggle(transition); } catch (err) { say(`Breakpoint refused: ${err.message}`, true); }
    },
    async step() {
      try { await attachment.step(); } catch (err) { say(err.message, true); }
    },
    async resume() {
      try { await attachment.resume(); } catch (err) { say(err.message, true); }
    },
    async kill() {
      try { await attachment.kill(); say(`${attachment.instance.instance_id} killed.`); } catch (err) { say(err.message, true); }
    },
    async detach() {
      await attachment.detach();
      say("Detached: its breakpoints are cleared.");
    },
  };

  const versionsPath = (v) => `/api/net-editor/versions/${encodeURIComponent(ui.versions.net)}/${v}`;
  const library = {
    async publish(form) {
      const name = model.doc.id;
      let saved;
      try {
        const doc = structuredClone(model.doc);
        saved = await api.post("/api/net-editor/publish", { net: doc, note: form.get("note") ?? "" });
        model.published(doc);
      } catch (err) {
        say(`Not published: ${err.message}`, true);
        return;
      }
      // Published: what the page reads after it (the library, the robots, the versions) may
      // fail without taking that back.
      const published = `${name} version ${saved.version} published: robots start it at their next task.`;
      ui.libraryNet = name;
      let stale = "";
      try {
        ui.library = await api.get("/api/nets");
        await attachment.loadTargets();
      } catch (err) {
        stale = ` The library's list could not be read again (${err.message}): reload the page to see it.`;
      }
      await loadVersions(name);
      say(`${published}${stale}`);
    },
    async open(version) {
      if (!(await mayDrop(`opening version ${version}`))) return;
      try {
        model.open(await api.get(versionsPath(version)));
        opened();
        say(`${ui.versions.net} version ${version} opened${version === ui.versions.live ? "" : " (not the live one: publish it, or restore it, to put it back to work)"}.`);
      } catch (err) {
        say(err.message, true);
      }
    },
    async compare(old, current) {
      try {
        ui.diff = await api.get(`/api/net-editor/diff/${encodeURIComponent(ui.versions.net)}?old=${old}&new=${current}`);
        draw();
      } catch (err) {
        say(err.message, true);
      }
    },
    async restore(version) {
      const name = ui.versions.net;
      try {
        const saved = await api.post(`/api/net-editor/restore/${encodeURIComponent(name)}/${version}`, {});
        await openLibrary(name, false);
        say(`${name} version ${version} restored as version ${saved.version}: robots start it at their next task.`);
      } catch (err) {
        say(`Not restored: ${err.message}`, true);
      }
    },
  };

  /** Open a PNML file's text (the file input's, or the benchmark's); resolves once it is
   * drawn and checked. */
  async function openPnml(text, name) {
    if (!(await mayDrop(`opening ${name}`))) return;
    try {
      const reply = await sendFile("/api/net-editor/import", text);
      model.open(reply.net);
      opened();
      say(`${name} opened${reply.net.layout === "layered" ? " (it had no drawing: laid out in layers)" : ""}.`);
      await model.checked;
    } catch (err) {
      say(`${name} cannot be opened: ${err.message}`, true);
    }
  }
  ui.openPnml = openPnml;

  async function openFile(input) {
    const file = input.files?.[0];
    if (!file) return;
    await openPnml(await file.text(), file.name);
    input.value = "";
  }

  async function exportPnml() {
    try {
      const blob = await api.post("/api/net-editor/export", model.doc);
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = `${model.doc.id}.pnml`;
      a.click();
      say(`${model.doc.id}.pnml exported${model.problems.length ? ` (with ${model.problems.length} problem(s): guidebot petri check will refuse it)` : ""}.`);
    } catch (err) {
      say(`Export refused: ${err.message}`, true);
    }
  }

  document.addEventListener("keydown", (e) => {
    if (/** @type {Element} */ (e.target).closest?.("input, textarea, select")) return;
    if ((e.ctrlKey || e.metaKey) && e.key === "z" && !readOnly) { e.preventDefault(); model.undo(); }
    if ((e.ctrlKey || e.metaKey) && (e.key === "y" || (e.shiftKey && e.key === "Z")) && !readOnly) { e.preventDefault(); model.redo(); }
    if ((e.key === "Delete" || e.key === "Backspace") && ui.selected && !readOnly) { e.preventDefault(); remove(ui.selected.kind, ui.selected.id); }
    if ((e.ctrlKey || e.metaKey) && e.key === "c" && !readOnly) { e.preventDefault(); copy(); }
    if ((e.ctrlKey || e.metaKey) && e.key === "v" && !readOnly) { e.preventDefault(); paste(); }
    if (e.key === "Escape") { canvas.pending = null; select(null); }
  });
  model.addEventListener("change", () => { if (ui.run) stopSimulating(); ui.analysis = null; draw(); });

  async function analyse() {
    try {
      ui.analysis = await api.post("/api/net-editor/analyse", { net: model.doc });
      draw();
    } catch (err) {
      say(`Analysis refused: ${err.message}`, true);
    }
  }

  function analysisView(a) {
    const summary = a.bounded === false
      ? `Unbounded: ${a.unbounded_places.join(", ")} can grow for ever.`
      : a.bounded ? `Bounded: at most ${a.bound} token(s) in a place, ${a.states} marking(s) in all.`
        : `Gave up after ${a.states} markings: boundedness not known (at most ${a.bound} token(s) seen in a place).`;
    return html`<div id="analysis" role="status"><p>${summary}</p>
      <p>${a.dead_transitions.length ? html`${a.complete ? "Never fire" : "Fire in none of the markings explored"}:
        ${a.dead_transitions.map((t, i) => html`${i ? ", " : ""}<button type="button" class="link" @click=${() => select("transition", t)}>${t}</button>`)}`
        : a.complete ? "Every transition can fire." : "Every transition fired in the markings explored."}
      ${a.dead_ends ? ` ${a.dead_ends} dead end(s): markings where nothing can fire and no final place is marked.` : ""}</p>
      <p class="muted">Every condition taken as possibly true: a transition found dead here is dead whatever the robot answers.</p></div>`;
  }
  model.addEventListener("checked", () => draw());

  function elementList(doc, byElement) {
    const item = (kind, id, label) => {
      const bad = byElement.has(`${kind}:${id}`);
      const current = ui.selected?.kind === kind && ui.selected.id === id;
      return html`<li><button type="button" class=${`element${bad ? " has-issue" : ""}${current ? " current" : ""}`}
        aria-current=${current ? "true" : "false"} @click=${() => select(kind, id)}>${label}${bad ? " ⚠" : ""}</button></li>`;
    };
    return html`
      <h2>Net</h2><ul class="elements">${item("net", doc.id, `${doc.id} (parameters, description)`)}</ul>
      <h2 id="places-title">Places (${doc.places.length})</h2>
      <ul class="elements" aria-labelledby="places-title">${doc.places.map((p) => item("place", p.id, p.name && p.name !== p.id ? `${p.name} (${p.id})` : p.id))}</ul>
      <h2 id="transitions-title">Transitions (${doc.transitions.length})</h2>
      <ul class="elements" aria-labelledby="transitions-title">${doc.transitions.map((t) => item("transition", t.id, t.name && t.name !== t.id ? `${t.name} (${t.id})` : t.id))}</ul>
      <h2 id="arcs-title">Arcs (${doc.arcs.length})</h2>
      <ul class="elements" aria-labelledby="arcs-title">${doc.arcs.map((a) => item("arc", a.id, `${a.source} → ${a.target}${a.weight > 1 ? ` ×${a.weight}` : ""}`))}</ul>`;
  }

  function problemTarget(key) {
    const [kind, ...rest] = key.split(":");
    const id = rest.join(":");
    if (kind === "net" || kind === "param") return () => select("net", model.doc.id);
    return () => select(kind, id);
  }

  function draw() {
    const doc = model.doc;
    const byElement = model.problemsByElement();
    const count = model.problems.length;
    if (ui.selected && ui.selected.kind !== "net" && !(ui.selected.kind === "arc" ? doc.arcs.some((a) => a.id === ui.selected.id) : model.node(ui.selected.id))) ui.selected = null;
    render(html`
      <span>${me.name} <span class="badge">${me.role}</span>${readOnly ? html` <span class="badge">read only</span>` : nothing}</span>
      <label>Library net <select id="library-select" @change=${(e) => { ui.libraryNet = e.target.value; }}>
        ${ui.library.map((n) => html`<option value=${n} ?selected=${n === ui.libraryNet}>${n}</option>`)}</select></label>
      <button type="button" class="secondary" @click=${() => openLibrary(ui.libraryNet || ui.library[0])}>Open</button>
      <label>Open a PNML file <input type="file" accept=".pnml,.xml,application/xml,text/xml" @change=${(e) => openFile(e.target)}></label>
      ${readOnly ? nothing : html`<button type="button" class="secondary" @click=${async () => { if (!(await mayDrop("a new net"))) return; model.open(emptyNet()); opened(); select("net", "new_net"); }}>New net</button>`}
      ${readOnly ? nothing : html`
        <button type="button" class="secondary" ?disabled=${!model.undoStack.length} @click=${() => model.undo()}
          title=${model.undoStack.length ? `Undo ${model.undoStack.at(-1).label}` : "Nothing to undo"}>Undo</button>
        <button type="button" class="secondary" ?disabled=${!model.redoStack.length} @click=${() => model.redo()}>Redo</button>`}
      <button type="button" ?disabled=${!doc} @click=${exportPnml}>Export PNML</button>
      <span id="problem-count" role="status" class=${count ? "error" : "ok-text"}>${!doc ? "" : count ? `${count} problem(s)` : "No problems"}</span>
      ${!readOnly && model.unpublished ? html`<span id="unpublished" class="warn-text">Changes not published</span>` : nothing}`, $("bar"));
    render(ui.notice ? html`<div class=${`notice ${ui.notice.error ? "error" : "ok"}`} role=${ui.notice.error ? "alert" : "status"}>${ui.notice.text}</div>` : nothing, $("notices"));
    if (!doc) {
      render(html`<p class="muted">Open a net of the library or a PNML file${readOnly ? "" : ", or start a new net"}.</p>`, $("lists"));
      render(attachPanel(ui, attachment, attaching), $("details"));
      return;
    }
    render(elementList(doc, byElement), $("lists"));
    const zoom = html`<span class="zoom"><button type="button" class="secondary small" aria-label="Zoom in" @click=${() => canvas.zoomBy(1.25)}>+</button>
      <button type="button" class="secondary small" aria-label="Zoom out" @click=${() => canvas.zoomBy(0.8)}>−</button>
      <button type="button" class="secondary small" @click=${() => { canvas.fit(model.doc); canvas.redraw(); }}>Fit</button></span>`;
    render(readOnly ? html`${zoom}<span class="muted">Read only: your role may not publish nets.</span>` : html`${zoom}
      <fieldset class="tools"><legend class="sr-only">Tool</legend>
        ${[["select", "Select and move"], ["place", "Add place"], ["transition", "Add transition"], ["arc", "Add arc"]].map(([t, label]) => html`
          <label><input type="radio" name="tool" value=${t} .checked=${ui.tool === t}
            @change=${() => { ui.tool = t; canvas.pending = null; draw(); }}> ${label}</label>`)}
      </fieldset>
      <button type="button" class="secondary small" ?disabled=${!ui.group.size} @click=${copy}>Copy</button>
      <button type="button" class="secondary small" ?disabled=${!ui.clipboard} @click=${paste}>Paste</button>
      ${ui.group.size > 1 ? html`<button type="button" class="danger small" @click=${() => remove("place", [...ui.group][0])}>Delete ${ui.group.size} nodes</button>`
        : ui.selected && ui.selected.kind !== "net" ? html`<button type="button" class="danger small" @click=${() => remove(ui.selected.kind, ui.selected.id)}>Delete ${ui.selected.kind} ${ui.selected.id}</button>` : nothing}
      <span class="muted">${ui.tool === "arc" ? "Click the arc's source, then its target." : ui.tool === "select" ? "Drag a node to move it (Shift+click selects several, Shift+drag the background selects those inside); drag the background to pan; the wheel zooms." : "Click the drawing where it goes."}</span>`, $("toolbar"));
    for (const id of [...ui.group]) if (!model.node(id)) ui.group.delete(id);
    const live = !ui.run && attachment.instance?.net === doc.id && !attachment.ended;
    canvas.draw(doc, { tool: ui.tool, selected: ui.selected, group: ui.group, problems: byElement, readOnly,
      marking: ui.run?.marking() ?? (live ? attachment.marking : null), fired: ui.run?.fired() ?? (live ? attachment.last : []) });
    render(html`
      <section aria-labelledby="details-title"><h2 id="details-title">${ui.selected ? `${ui.selected.kind} ${ui.selected.id}` : "Selected element"}</h2>
        ${ui.selected ? detailsForm({ doc, selected: ui.selected, vocabulary: ui.vocabulary, library: ui.library, readOnly, problems: byElement,
          edit: (label, fn) => model.edit(label, fn), rename, remove }) : html`<p class="muted">Select an element in the drawing or the list.</p>`}</section>
      <section aria-labelledby="problems-title"><h2 id="problems-title">Problems (${count})</h2>
        ${count ? html`<ul class="problems" id="problems">${model.problems.map((p) => html`<li><button type="button" class="link" @click=${problemTarget(p.element)}>${p.element}</button>: ${p.message}</li>`)}</ul>`
          : html`<p class="ok-text" id="problems">The net passes every check of <code>guidebot petri check</code>.</p>`}
        <button type="button" class="secondary" @click=${analyse}>Analyse the reachability graph</button>
        ${ui.analysis ? analysisView(ui.analysis) : nothing}</section>
      ${libraryPanel(ui, library)}
      ${attachPanel(ui, attachment, attaching)}
      ${simulationPanel(ui, simulation)}`, $("details"));
  }

  try {
    ui.library = await api.get("/api/nets");
    await attachment.loadTargets();
  } catch (err) {
    say(err.message, true);
  }
  ui.libraryNet = ui.library[0] ?? "";
  draw();
}

session.boot();
