// The site editor's model: the shared draft on the server, this tab's copy, undo and redo.
// Every edit is a snapshot on the undo stack and is saved at once (PUT /api/site/draft with the
// revision it started from); the server answers with the draft's problems. A save refused
// because someone else saved in between (409) keeps this tab's edits: reload or merge.
import { ApiError } from "/lib/rest.js";

const SECTIONS = [
  "floors", "nodes", "edges", "pois", "tours", "charging_stations", "wait_points", "areas",
  "doors", "elevators", "buttons", "modules", "robots",
];

/** An element's identity within its section (robots by name, edges by their two nodes). */
export function elementKey(section, item) {
  if (!item || typeof item !== "object") return JSON.stringify(item);
  if (section === "edges") return `${item.a}->${item.b}`;
  if (section === "robots") return String(item.name);
  return item.id !== undefined ? String(item.id) : JSON.stringify(item);
}

/** Three-way merge by element: my changes since `base` applied onto `theirs`. */
export function mergeDrafts(base, mine, theirs) {
  const out = structuredClone(theirs);
  for (const key of new Set([...Object.keys(base), ...Object.keys(mine)])) {
    if (!SECTIONS.includes(key)) {
      if (JSON.stringify(base[key]) !== JSON.stringify(mine[key])) out[key] = mine[key];
      continue;
    }
    const index = (items) => new Map((items ?? []).map((i) => [elementKey(key, i), i]));
    const b = index(base[key]);
    const m = index(mine[key]);
    let list = [...(out[key] ?? [])];
    for (const [k, item] of m) {
      const before = b.get(k);
      if (before && JSON.stringify(before) === JSON.stringify(item)) continue;
      const at = list.findIndex((i) => elementKey(key, i) === k);
      if (at >= 0) list[at] = item;
      else list.push(item);
    }
    for (const k of b.keys()) {
      if (!m.has(k)) list = list.filter((i) => elementKey(key, i) !== k);
    }
    // A reordered section (tour points live inside elements; this is for the lists).
    out[key] = list;
  }
  return out;
}

export class DraftModel extends EventTarget {
  constructor(api) {
    super();
    this.api = api;
    this.doc = null;
    this.synced = null; // the server's draft at `revision`
    this.revision = 0;
    this.baseVersion = 0;
    this.liveVersion = 0;
    this.issues = [];
    this.undoStack = [];
    this.redoStack = [];
    this.conflict = null; // {message, revision, updated_by} after a refused save
    this.saving = Promise.resolve();
    this.saved = 0; // edits saved (for tests and the benchmark)
    this.unsaved = false; // the last save failed: this tab holds an edit the shared draft lacks
  }

  async load() {
    const state = await this.api.get("/api/site/draft");
    this.#take(state);
    this.undoStack = [];
    this.redoStack = [];
    this.conflict = null;
    this.unsaved = false;
    this.#changed();
  }

  #take(state) {
    this.doc = structuredClone(state.draft);
    this.synced = structuredClone(state.draft);
    this.revision = state.revision;
    this.baseVersion = state.base_version;
    this.liveVersion = state.live_version;
    this.issues = state.issues;
  }

  #changed() {
    this.dispatchEvent(new Event("change"));
  }

  /** Apply one edit (a function changing the document), undoable, and save it. */
  edit(label, change) {
    const before = structuredClone(this.doc);
    change(this.doc);
    this.undoStack.push({ label, doc: before });
    this.redoStack = [];
    this.#changed();
    return this.save();
  }

  undo() {
    const step = this.undoStack.pop();
    if (!step) return Promise.resolve();
    this.redoStack.push({ label: step.label, doc: structuredClone(this.doc) });
    this.doc = step.doc;
    this.#changed();
    return this.save();
  }

  redo() {
    const step = this.redoStack.pop();
    if (!step) return Promise.resolve();
    this.undoStack.push({ label: step.label, doc: structuredClone(this.doc) });
    this.doc = step.doc;
    this.#changed();
    return this.save();
  }

  /** Save the current document (queued: one save at a time, in order). */
  save() {
    this.saving = this.saving.then(() => this.#saveNow());
    return this.saving;
  }

  async #saveNow() {
    if (this.conflict) return;
    const doc = structuredClone(this.doc);
    try {
      const reply = await this.api.put("/api/site/draft", { draft: doc, revision: this.revision });
      this.revision = reply.revision;
      this.issues = reply.issues;
      this.synced = doc;
      this.saved += 1;
      this.unsaved = false;
    } catch (err) {
      if (err instanceof ApiError && err.status === 409) {
        const d = err.detail ?? {};
        this.conflict = { message: d.msg ?? err.message, revision: d.revision, by: d.updated_by };
      } else {
        this.unsaved = true;
        this.dispatchEvent(new CustomEvent("failure", { detail: err }));
      }
    }
    this.#changed();
  }

  /** After a conflict: throw this tab's edits away and take the shared draft. */
  async reload() {
    await this.load();
  }

  /** After a conflict: apply this tab's edits onto the shared draft, then save. */
  async merge() {
    const theirs = await this.api.get("/api/site/draft");
    const merged = mergeDrafts(this.synced, this.doc, theirs.draft);
    this.#take(theirs);
    this.conflict = null;
    this.undoStack.push({ label: "merge", doc: structuredClone(this.doc) });
    this.doc = merged;
    this.#changed();
    return this.save();
  }

  /** Publish the shared draft. An edit whose save failed is saved first: publishing without it
   * would leave it out, and reloading the published draft would drop it from this tab too. */
  async publish(note = "") {
    await this.saving;
    if (this.unsaved) await this.save();
    if (this.unsaved) throw new Error("your last change is not saved on the server yet, so it would be left out: try again");
    const reply = await this.api.post("/api/site/publish", { revision: this.revision, note });
    await this.load();
    return reply.version;
  }

  /** Problems by element: "section/index" -> [issue]; and the issues of the document. */
  issuesByElement() {
    const map = new Map();
    for (const issue of this.issues) {
      const m = /^([a-z_]+)\[(\d+)\]/.exec(issue.loc);
      const key = m ? `${m[1]}/${m[2]}` : "(document)";
      map.set(key, [...(map.get(key) ?? []), issue]);
    }
    return map;
  }

  /** A readable place for an issue: "tours ground: points[1]". */
  describeLoc(loc) {
    const m = /^([a-z_]+)\[(\d+)\]\.?(.*)$/.exec(loc);
    if (!m) return loc;
    const item = this.doc?.[m[1]]?.[Number(m[2])];
    const name = item ? elementKey(m[1], item) : `#${m[2]}`;
    return `${m[1]} ${name}${m[3] ? `: ${m[3]}` : ""}`;
  }
}

export { SECTIONS };
