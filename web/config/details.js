// The site editor's right column: the selected element's form (or the fire alarm's), the
// draft's problems (each one a link to its element), the published versions and the YAML file.
import { html, nothing } from "lit-html";
import { emergencyForm } from "/config/emergency.js";
import { KINDS, elementForm } from "/config/forms.js";
import { startCalibration } from "/config/plan.js";
import { versionsSection } from "/config/versions.js";
import { yamlSection } from "/config/yaml.js";

/**
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function detailsView(ui) {
  const { model, select } = ui;
  const doc = model.doc;
  return html`
      <section aria-labelledby="details-title"><h2 id="details-title" class="sr-only">Selected element</h2>
        ${ui.section === "emergency" ? emergencyForm({ doc, issues: model.issues, edit: (label, fn) => model.edit(label, fn) })
          : ui.selected ? elementForm(elementContext(ui, ui.selected.section, ui.selected.index)) : html`<p class="muted">Select an element on the plan or in the list.</p>`}</section>
      <section aria-labelledby="problems-title"><h2 id="problems-title">Problems (${model.issues.length})</h2>
        ${model.issues.length ? html`<ul class="problems">${model.issues.map((issue) => {
          const m = /^([a-z_]+)\[(\d+)\]/.exec(issue.loc);
          const go = () => (issue.loc.startsWith("emergency") ? select("emergency", null) : m && select(m[1], Number(m[2])));
          return html`<li><button type="button" class="link" @click=${go}>${model.describeLoc(issue.loc)}</button>: ${issue.msg}</li>`;
        })}</ul>` : html`<p class="ok-text">The draft passes every check of <code>guidebot site check</code>.</p>`}</section>
      ${versionsSection(ui)}
      ${yamlSection(ui)}`;
}

/**
 * What an element's form may do (web/config/forms.js): edit the draft, upload a file, give a
 * robot a new token, delete the element, calibrate a floor.
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {string} section
 * @param {number} index
 */
function elementContext(ui, section, index) {
  const { model } = ui;
  return {
    doc: model.doc, section, index,
    issues: model.issuesByElement().get(`${section}/${index}`) ?? [],
    edit: (label, fn) => model.edit(label, fn),
    upload: (kind, input, done) => upload(ui, kind, input, done),
    regenerate: (name) => regenerate(ui, name),
    remove: (s, i) => {
      model.edit(`delete ${KINDS[s].one}`, (d) => d[s].splice(i, 1));
      ui.select(s, null);
    },
    calibrate: (i) => startCalibration(ui, i),
  };
}

/**
 * Upload a plan or a media file; `done` gets the path the server stored it under.
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {string} kind  "plan" or "media"
 * @param {HTMLInputElement} input
 * @param {(path: string) => void} done
 */
async function upload(ui, kind, input, done) {
  const file = input.files?.[0];
  if (!file) return;
  try {
    const reply = await ui.sendFile("POST", `/api/site/uploads/${kind}`, file, file.type || "application/octet-stream");
    done(reply.path);
    ui.say(`${file.name} uploaded.`);
  } catch (err) {
    ui.say(`Upload refused: ${err.message}`, true);
  }
  input.value = "";
}

/**
 * Give robot `name` a new token (shown once, until "Done").
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {string} name
 */
async function regenerate(ui, name) {
  const { api, model } = ui;
  await model.saving;
  try {
    const reply = await api.post(`/api/site/draft/robots/${encodeURIComponent(name)}/token`, { revision: model.revision });
    await model.load();
    ui.token = { robot: name, token: reply.token };
    ui.draw();
  } catch (err) {
    ui.say(err.message, true);
  }
}
