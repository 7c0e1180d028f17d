// The site editor's left column: the element kinds (with their counts and problems) and the
// elements of the kind chosen, to select one or add one.
import { html, nothing } from "lit-html";
import { KINDS, newElement } from "/config/forms.js";
import { counted } from "/lib/dom.js";

/**
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {Map<string, any[]>} byElement  the draft's problems by "section/index"
 */
export function listsView(ui, byElement) {
  const { model, select } = ui;
  const doc = model.doc;
  const em = doc.emergency;
  const emIssues = model.issues.filter((i) => i.loc.startsWith("emergency")).length;
  return html`
      <nav aria-label="Element kinds"><ul class="kinds">${Object.entries(KINDS).map(([section, kind]) => {
        const bad = [...byElement.keys()].filter((k) => k.startsWith(`${section}/`)).length;
        return html`<li><button type="button" class=${ui.section === section ? "kind current" : "kind secondary"} aria-pressed=${ui.section === section ? "true" : "false"}
          @click=${() => select(section, null)}>${kind.label} (${(doc[section] ?? []).length})${bad ? html` <span class="error">⚠ ${bad}</span>` : nothing}</button></li>`;
      })}<li><button type="button" class=${ui.section === "emergency" ? "kind current" : "kind secondary"} aria-pressed=${ui.section === "emergency" ? "true" : "false"}
          @click=${() => select("emergency", null)}>Fire alarm (${em ? counted(em.alarms.length, "input") : "none"})${emIssues ? html` <span class="error">⚠ ${emIssues}</span>` : nothing}</button></li></ul></nav>
      ${ui.section === "emergency" ? html`<h2 id="list-title">Fire alarm</h2>
      <p class="muted">${em ? `${counted(em.alarms.length, "alarm input")}, ${counted(em.safe_spots.length, "safe spot")}, ${counted(em.escape_routes.length, "escape route")}: edit them on the right, safe spots also on the plan.` : "Not set up yet."}</p>` : html`
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
      }}>Add ${KINDS[ui.section].one}</button>`}`;
}
