// The site editor's controller: the state every part reads (`ui`), its actions (select, say,
// draw), undo and redo from the keyboard, and the start (the draft, then the versions). Each
// part draws itself: the header bar and notices (bar.js), the element lists (lists.js), the
// plan (plan.js), the details column (details.js: the element's form, problems, versions.js,
// yaml.js) and the translations (translations.js). Sign-in: web/lib/session.js.
import { render } from "lit-html";
import { barView, noticesView } from "/config/bar.js";
import { detailsView } from "/config/details.js";
import { EditMap } from "/config/editmap.js";
import { listsView } from "/config/lists.js";
import { DraftModel } from "/config/model.js";
import { planToolbar, wirePlan } from "/config/plan.js";
import { mountTranslations } from "/config/translations.js";
import { loadVersions } from "/config/versions.js";

/**
 * The page's parts (ids in web/config/index.html).
 * @typedef {{editor: HTMLElement, connection: HTMLElement, bar: HTMLElement,
 *            notices: HTMLElement, lists: HTMLElement, mapToolbar: HTMLElement, map: HTMLElement,
 *            details: HTMLElement, translations: HTMLElement, views: HTMLElement,
 *            columns: HTMLElement}} EditorParts
 */

/**
 * The signed-in person or token, as GET /api/me answers.
 * @typedef {{name: string, role: string}} Me
 */

/**
 * The editor's state and actions, shared by its parts.
 * @typedef {object} EditorUi
 * @property {Me} me
 * @property {DraftModel} model  the draft (web/config/model.js)
 * @property {import("/lib/rest.js").Api} api
 * @property {import("/lib/hub.js").HubClient} hub
 * @property {EditMap} map
 * @property {(method: string, path: string, body: BodyInit, type: string) => Promise<any>} sendFile
 * @property {string} section  the element kind listed ("pois", "edges", ..., "emergency")
 * @property {{section: string, index: number} | null} selected
 * @property {string} tool  the plan's tool: "select", "node", "edge", "safe" or "calibrate"
 * @property {boolean} oneWay  new edges are one-way
 * @property {string | null} edgeFrom  the first node of an edge being added
 * @property {{index: number, points: {x: number, y: number}[]} | null} calibration
 * @property {{text: string, error: boolean} | null} notice
 * @property {any} rollout  the last site_rollout (docs/messages.md)
 * @property {any[]} versions  the published versions, newest first
 * @property {{title: string, changes: any[]} | null} diff
 * @property {any[] | null} importErrors  the problems of the last YAML file refused
 * @property {string | null} floor  the floor shown on the plan
 * @property {{robot: string, token: string} | null} [token]  a robot's new token, shown once
 * @property {(section: string, index: number | null) => void} select
 * @property {(text: string, error?: boolean) => void} say  a notice (an error when `error`)
 * @property {() => void} draw
 */

/**
 * Start the editor for `me`: the live connection (publish roll-outs), the draft, the versions.
 * @param {import("/lib/session.js").StaffSession<Me>} session
 * @param {Me} me
 * @param {EditorParts} parts
 * @returns {Promise<void>}
 */
export async function startEditor(session, me, parts) {
  parts.editor.hidden = false;
  const { api } = session;
  const model = new DraftModel(api);
  const hub = session.connect(parts.connection);
  hub.subscribe("site_rollout");
  /** @type {EditorUi} */
  const ui = {
    me, model, api, hub, section: "pois", selected: null, tool: "select", oneWay: false,
    edgeFrom: null, calibration: null, notice: null, rollout: null, versions: [], diff: null,
    importErrors: null, floor: null,
    map: new EditMap(parts.map, (url) => api.get(url)),
    sendFile: (method, path, body, type) => session.sendFile(method, path, body, type),
    select(section, index) {
      ui.section = section;
      ui.selected = index === null ? null : { section, index };
      draw();
    },
    say(text, error = false) {
      ui.notice = { text, error };
      draw();
    },
    draw: () => draw(),
  };
  installProbe(ui);
  hub.on("site_rollout", (m) => { ui.rollout = m.payload; draw(); });
  model.addEventListener("failure", (e) => { ui.notice = { error: true, text: `Your last change is not saved: ${/** @type {CustomEvent} */ (e).detail.message} The next change, or Publish, tries again.` }; draw(); });
  model.addEventListener("change", () => draw());
  wirePlan(ui);

  document.addEventListener("keydown", (e) => {
    if (/** @type {HTMLElement} */ (e.target).closest?.("input, textarea, select")) return;
    if ((e.ctrlKey || e.metaKey) && e.key === "z") { e.preventDefault(); model.undo(); }
    if ((e.ctrlKey || e.metaKey) && (e.key === "y" || (e.shiftKey && e.key === "Z"))) { e.preventDefault(); model.redo(); }
  });

  function draw() {
    if (!model.doc) return;
    const doc = model.doc;
    if (!doc.floors.some((f) => f.id === ui.floor)) ui.floor = doc.floors[0]?.id;
    const byElement = model.issuesByElement();
    if (ui.selected && !doc[ui.selected.section]?.[ui.selected.index]) ui.selected = null;
    ui.map.draw(doc, ui.floor, byElement, ui.selected);
    render(barView(ui), parts.bar);
    render(noticesView(ui), parts.notices);
    render(listsView(ui, byElement), parts.lists);
    render(planToolbar(ui), parts.mapToolbar);
    render(detailsView(ui), parts.details);
  }

  // Load last, once every handler above exists: the page draws as soon as the draft arrives, and a
  // control used before the version list is in must not reach a helper that is not declared yet.
  await model.load();
  ui.floor = model.doc.floors[0].id;
  await loadVersions(ui);
  draw();
  mountTranslations({ model, api, sendFile: ui.sendFile, root: parts.translations, nav: parts.views, columns: parts.columns });
}

/**
 * The editor's probe, for the benchmark (bench/reconfigure.py) and the browser tests: where a
 * site point is on the screen (to click the plan at x, y metres, where an installer clicks a
 * stand), and the save queue (edits are saved in the background, which the page does not show;
 * a test that reads the server's draft waits for it). Not the editor's state: tests act and
 * look through the page itself.
 * @param {EditorUi} ui
 */
function installProbe(ui) {
  /** @type {any} */ (window).guidebotProbe = Object.freeze({
    /** @param {number} x @param {number} y  metres, on the floor shown */
    pointFor: (x, y) => ui.map.pointFor(x, y),
    /** Resolves once every edit made so far is saved on the server. */
    saved: () => ui.model.saving.then(() => true),
  });
}
