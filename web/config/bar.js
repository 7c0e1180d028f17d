// The site editor's header bar (who, the draft's revision, undo and redo, publish, the problem
// count) and its notices (a change not saved, what the last action did, a robot's new token).
import { html, nothing } from "lit-html";
import { publish } from "/config/versions.js";
import { counted } from "/lib/dom.js";

/**
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function barView(ui) {
  const { me, model } = ui;
  const count = model.issues.length;
  return html`
      <span>${me.name} <span class="badge">${me.role}</span></span>
      <span class="muted" id="draft-status">Draft revision ${model.revision} · live version ${model.liveVersion}${model.unsaved
        ? html` · <strong class="error">your last change is not saved</strong>` : nothing}</span>
      <button type="button" class="secondary" ?disabled=${!model.undoStack.length} @click=${() => model.undo()}
        title=${model.undoStack.length ? `Undo ${model.undoStack.at(-1).label}` : "Nothing to undo"}>Undo</button>
      <button type="button" class="secondary" ?disabled=${!model.redoStack.length} @click=${() => model.redo()}>Redo</button>
      <label>Note <input id="publish-note" placeholder="what changed" maxlength="500"></label>
      <button type="button" id="publish" ?disabled=${!!model.conflict} @click=${() => publish(ui)}
        aria-describedby="problem-count">Publish</button>
      <span id="problem-count" class=${count ? "error" : "ok-text"}>${count ? `${counted(count, "problem")}: publishing is refused` : "No problems"}</span>`;
}

/**
 * @param {import("/config/editor.js").EditorUi} ui
 */
export function noticesView(ui) {
  const { model } = ui;
  return html`
      ${model.conflict ? html`<div class="notice error" role="alert"><strong>Your last change was not saved.</strong> ${model.conflict.message}
        <button type="button" @click=${() => model.reload()}>Reload the draft (drop my changes)</button>
        <button type="button" class="secondary" @click=${() => model.merge()}>Merge my changes into it</button></div>` : nothing}
      ${ui.notice ? html`<div class=${`notice ${ui.notice.error ? "error" : "ok"}`} role=${ui.notice.error ? "alert" : "status"}>${ui.notice.text}</div>` : nothing}
      ${ui.token ? html`<div class="notice ok" role="status">New token for robot ${ui.token.robot} (shown once: copy it now, then publish):
        <output class="token">${ui.token.token}</output> <button type="button" class="secondary" @click=${() => { ui.token = null; ui.draw(); }}>Done</button></div>` : nothing}`;
}
