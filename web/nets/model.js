// The net being edited: the editor's JSON document (docs/nets.md), undo and redo, and the
// engine's problems, re-checked by the server (POST /api/net-editor/check) after every edit.

const LIMIT = 200; // undo steps kept

export class NetModel extends EventTarget {
  constructor(api) {
    super();
    this.api = api;
    this.doc = null;
    this.undoStack = [];
    this.redoStack = [];
    this.problems = [];
    this.checked = null; // a promise: the check of the current document
    this.sequence = 0;
    this.kept = ""; // the document as opened or last published: edits since are this tab's only
  }

  /** Start over with a document (a library net, a file, a new net): no history. */
  open(doc) {
    this.doc = structuredClone(doc);
    this.kept = JSON.stringify(this.doc);
    this.undoStack = [];
    this.redoStack = [];
    this.changed();
  }

  /** Whether the net has edits that are nowhere but in this tab (not published since opened). */
  get unpublished() {
    return this.doc !== null && JSON.stringify(this.doc) !== this.kept;
  }

  /** The document as it stands is published: nothing of it is this tab's only. */
  published(doc) {
    this.kept = JSON.stringify(doc);
  }

  /** One undoable edit: `fn` changes the document in place. */
  edit(label, fn) {
    const before = structuredClone(this.doc);
    fn(this.doc);
    this.undoStack.push({ label, doc: before });
    if (this.undoStack.length > LIMIT) this.undoStack.shift();
    this.redoStack = [];
    this.changed();
  }

  undo() {
    const step = this.undoStack.pop();
    if (!step) return;
    this.redoStack.push({ label: step.label, doc: this.doc });
    this.doc = step.doc;
    this.changed();
  }

  redo() {
    const step = this.redoStack.pop();
    if (!step) return;
    this.undoStack.push({ label: step.label, doc: this.doc });
    this.doc = step.doc;
    this.changed();
  }

  changed() {
    this.dispatchEvent(new Event("change"));
    this.checked = this.check();
  }

  /** Ask the server; only the answer to the latest document is kept. */
  async check() {
    const mine = ++this.sequence;
    try {
      const reply = await this.api.post("/api/net-editor/check", this.doc);
      if (mine !== this.sequence) return;
      this.problems = reply.problems;
    } catch (err) {
      if (mine !== this.sequence) return;
      const detail = Array.isArray(err.detail) ? err.detail.map((d) => `${(d.loc ?? []).slice(1).join(".")}: ${d.msg}`).join("; ") : err.message;
      this.problems = [{ element: "net", message: `the document cannot be checked: ${detail}` }];
    }
    this.dispatchEvent(new Event("checked"));
  }

  /** Problems by element key ("place:p1", "transition:t1", "arc:a1", "param:x", "net"). */
  problemsByElement() {
    const out = new Map();
    for (const p of this.problems) {
      if (!out.has(p.element)) out.set(p.element, []);
      out.get(p.element).push(p.message);
    }
    return out;
  }

  node(id) {
    return this.doc.places.find((p) => p.id === id) ?? this.doc.transitions.find((t) => t.id === id) ?? null;
  }

  /** A fresh id with a prefix: p1, p2, ... not used by any element. */
  freshId(prefix) {
    const used = new Set([...this.doc.places, ...this.doc.transitions, ...this.doc.arcs].map((e) => e.id));
    for (let i = 1; ; i += 1) if (!used.has(`${prefix}${i}`)) return `${prefix}${i}`;
  }
}

/** An empty task net. */
export function emptyNet(id = "new_net") {
  return { id, name: id, description: "", endless: false, task: true, params: [], places: [], transitions: [], arcs: [] };
}
