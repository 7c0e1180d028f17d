// The site editor's YAML section: the draft exported as a site file, a site file imported into
// the draft (its problems listed by line when refused).
import { html, nothing } from "lit-html";

/**
 * @param {import("/config/editor.js").EditorUi} ui
 */
async function exportYaml(ui) {
  try {
    const blob = await ui.api.get("/api/site/draft/export");
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = "site.yaml";
    a.click();
  } catch (err) {
    ui.say(`Export refused: ${err.message}`, true);
  }
}

/**
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {HTMLInputElement} input
 */
async function importYaml(ui, input) {
  const { model, say } = ui;
  const file = input.files?.[0];
  if (!file) return;
  await model.saving;
  try {
    await ui.sendFile("POST", `/api/site/draft/import?revision=${model.revision}`, await file.text(), "application/yaml");
    ui.importErrors = null;
    await model.load();
    say(`${file.name} imported into the draft.`);
  } catch (err) {
    ui.importErrors = Array.isArray(err.detail) ? err.detail : [{ loc: "(document)", msg: err.message, line: null }];
    say(`${file.name} refused: ${ui.importErrors.length} problem(s).`, true);
  }
  input.value = "";
}

/**
 * The "Site file (YAML)" section.
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function yamlSection(ui) {
  return html`<section aria-labelledby="yaml-title"><h2 id="yaml-title">Site file (YAML)</h2>
        <button type="button" class="secondary" @click=${() => exportYaml(ui)}>Export draft as YAML</button>
        <label>Import YAML into the draft <input type="file" accept=".yaml,.yml,application/yaml,text/yaml" @change=${(e) => importYaml(ui, e.target)}></label>
        ${ui.importErrors ? html`<ul class="problems" aria-label="Problems in the imported file">${ui.importErrors.map((i) => html`<li>line ${i.line ?? "?"}: ${i.loc}: ${i.msg}</li>`)}</ul>` : nothing}</section>`;
}
