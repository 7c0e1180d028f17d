// The site editor's versions: publish the draft, the roll-out to the robots, the published
// versions with what each changed, and rolling back to one.
import { html, nothing } from "lit-html";
import { confirmAction } from "/lib/confirm.js";
import { counted, dateTime } from "/lib/dom.js";
import { ApiError } from "/lib/rest.js";
import { translationWarning } from "/config/translations.js";

/**
 * Read the published versions (newest first) into the editor's state.
 * @param {import("/config/editor.js").EditorUi} ui
 */
export async function loadVersions(ui) {
  ui.versions = await ui.api.get("/api/site/versions");
}

/**
 * Publish the draft with the note typed in the bar; the page says the new version, or why not.
 * @param {import("/config/editor.js").EditorUi} ui
 */
export async function publish(ui) {
  const { api, model, say } = ui;
  try {
    const input = /** @type {HTMLInputElement | null} */ (document.getElementById("publish-note"));
    const note = input?.value ?? "";
    const untranslated = await translationWarning(api, model);
    const version = await model.publish(note);
    // The note went with this version: the next one must not carry it unasked.
    if (input) input.value = "";
    ui.rollout = ui.rollout?.version === version ? ui.rollout : { version, expected: [], loaded_ms: {}, complete: false };
    await loadVersions(ui);
    say(`Version ${version} is live.${untranslated}`);
  } catch (err) {
    if (err instanceof ApiError && err.status === 422) say(`Publish refused: ${counted(err.detail.length, "problem")}, see the list.`, true);
    else say(`Publish refused: ${err.detail?.msg ?? err.message}`, true);
  }
}

/**
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {number} version
 */
async function rollback(ui, version) {
  const { api, model, say } = ui;
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
    await loadVersions(ui);
    say(`Rolled back: version ${version} is live again as version ${reply.version}.`);
  } catch (err) {
    say(err.message, true);
  }
}

/**
 * @param {import("/config/editor.js").EditorUi} ui
 * @param {number | string} from
 * @param {number | string} to
 * @param {string} title
 */
async function showDiff(ui, from, to, title) {
  ui.diff = { title, changes: await ui.api.get(`/api/site/diff?from=${from}&to=${to}`) };
  ui.draw();
}

/**
 * The "Published versions" section: the roll-out, the versions, the changes shown.
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function versionsSection(ui) {
  const { model } = ui;
  return html`<section aria-labelledby="publish-title"><h2 id="publish-title">Published versions</h2>
        ${ui.rollout ? html`<p role="status" id="rollout">${rolloutText(ui.rollout)}</p>` : nothing}
        <button type="button" class="secondary" @click=${() => showDiff(ui, model.liveVersion, "draft", "Draft compared with the live version")}>Changes in the draft</button>
        <table><caption class="sr-only">Published versions</caption><thead><tr><th>Version</th><th>By</th><th>When</th><th>Actions</th></tr></thead>
        <tbody>${ui.versions.map((v, i) => html`<tr><td>${v.version}${v.version === model.liveVersion ? " (live)" : ""}</td>
          <td>${v.published_by || "—"}</td><td>${dateTime(v.published_at)}${v.note ? html`<br><span class="muted">${v.note}</span>` : nothing}</td>
          <td>${ui.versions[i + 1] ? html`<button type="button" class="secondary small" aria-label=${`Changes in version ${v.version}`} @click=${() => showDiff(ui, ui.versions[i + 1].version, v.version, `Changes in version ${v.version}`)}>Changes</button>` : nothing}
          ${v.version !== model.liveVersion ? html`<button type="button" class="secondary small" aria-label=${`Roll back to version ${v.version}`} @click=${() => rollback(ui, v.version)}>Roll back</button>` : nothing}</td></tr>`)}</tbody></table>
        ${ui.diff ? html`<h3>${ui.diff.title}</h3><ul class="diff" aria-label=${ui.diff.title}>${ui.diff.changes.length ? ui.diff.changes.map((c) => html`<li class=${`diff-${c.change}`}>${c.text}</li>`) : html`<li>No changes.</li>`}</ul>` : nothing}</section>`;
}

/**
 * A roll-out in words: how many robots loaded the version, and how fast.
 * @param {{version: number, expected: string[], loaded_ms: Record<string, number>, complete: boolean, ms?: number}} r
 * @returns {string}
 */
export function rolloutText(r) {
  const n = r.expected.length;
  const done = Object.keys(r.loaded_ms).length;
  if (!n) return `Version ${r.version} is live (no robot connected).`;
  if (r.complete) return `Version ${r.version} reached ${n === 1 ? "its robot" : `all ${n} robots`} in ${Math.round(r.ms)} ms.`;
  return `Version ${r.version}: ${done} of ${counted(n, "robot")} updated…`;
}
