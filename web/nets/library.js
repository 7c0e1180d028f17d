// The net library panel of the RoboGraph editor (docs/nets.md, "Publish"): publish the net to
// the fleet, its published versions with who, when and why, a readable comparison of two
// versions, and restore (an old version published again).
import { html, nothing } from "lit-html";

const when = (seconds) => new Date(seconds * 1000).toLocaleString();

/** What the server keeps of the open net: `ui.versions` (null: never published nor shipped). */
export function libraryPanel(ui, actions) {
  const doc = ui.model.doc;
  const info = ui.versions;
  const problems = ui.model.problems.length;
  return html`<section aria-labelledby="library-title"><h2 id="library-title">Library and fleet</h2>
    ${ui.readOnly ? html`<p class="muted">Publishing is for those who may edit nets.</p>` : html`
      <form class="form" @submit=${(e) => { e.preventDefault(); actions.publish(new FormData(e.target)); e.target.reset(); }}>
        <div class="field"><label for="publish-note">What changed (kept in the history)</label>
          <input id="publish-note" name="note" maxlength="2000"></div>
        <button type="submit" ?disabled=${problems > 0}>Publish ${doc.id} to the fleet</button>
        ${problems ? html`<p class="muted">Fix the problems first: the library takes only nets the engine runs.</p>`
          : html`<p class="muted">Robots and the server start it at their next task; tasks running now finish on their version.</p>`}
      </form>`}
    ${info ? html`
      <h3 id="versions-title">Versions of ${info.net}</h3>
      <ol class="versions" aria-labelledby="versions-title" reversed>
        ${info.versions.map((v) => versionItem(ui, actions, info, v))}
        ${info.shipped ? versionItem(ui, actions, info, { version: 0, published_by: "", published_at: null, note: "the library folder's file" }) : nothing}
      </ol>
      ${ui.diff ? html`<div id="diff" role="status"><h3>Version ${ui.diff.old} → ${ui.diff.new}</h3>
        ${ui.diff.changes.length ? html`<ul class="diff">${ui.diff.changes.map((line) => html`<li class=${`diff-${line[0] === "+" ? "add" : line[0] === "-" ? "del" : "mod"}`}>${line}</li>`)}</ul>`
          : html`<p>The same net.</p>`}</div>` : nothing}`
      : html`<p class="muted">${doc.id} is not in the library yet: publishing adds it.</p>`}
  </section>`;
}

function versionItem(ui, actions, info, v) {
  const live = v.version === info.live;
  const label = v.version === 0 ? "Version 0 (shipped)" : `Version ${v.version}`;
  return html`<li class="version">
    <strong>${label}</strong>${live ? html` <span class="badge">live</span>` : nothing}
    ${v.published_at ? html`<span class="muted">${v.published_by || "?"}, ${when(v.published_at)}</span>` : nothing}
    ${v.note ? html`<div>${v.note}</div>` : nothing}
    <div class="bar">
      <button type="button" class="secondary small" aria-label=${`Open ${label.toLowerCase()}`} @click=${() => actions.open(v.version)}>Open</button>
      ${live ? nothing : html`<button type="button" class="secondary small" aria-label=${`Compare with live: ${label.toLowerCase()}`} @click=${() => actions.compare(v.version, info.live)}>Compare with live</button>`}
      ${live || ui.readOnly ? nothing : html`<button type="button" class="secondary small" aria-label=${`Restore ${label.toLowerCase()}`} @click=${() => actions.restore(v.version)}>Restore</button>`}
    </div></li>`;
}
