// Locks: every restricted area with holder and queue; force release with a confirmation.
import { html } from "lit-html";
import { duration } from "/lib/dom.js";

function confirmRelease(ui, lock) {
  const dialog = /** @type {HTMLDialogElement} */ (document.getElementById("confirm-release"));
  ui.releasing = lock;
  ui.draw();
  dialog.showModal();
}

function releaseDialog(ui) {
  const lock = ui.releasing;
  const close = () => /** @type {HTMLDialogElement} */ (document.getElementById("confirm-release")).close();
  const release = () => {
    close();
    ui.act(`Release area ${lock.area}`, () => ui.api.post(`/api/locks/${encodeURIComponent(lock.area)}/release`));
  };
  return html`<dialog id="confirm-release" aria-labelledby="confirm-title">
    ${lock
      ? html`<h3 id="confirm-title">Release area ${lock.area}?</h3>
        <p>${lock.holder} holds it${lock.state === "holder_offline" ? " and is offline" : ""}.
          Releasing it lets ${lock.waiting.length ? lock.waiting.join(", ") : "the next robot"} enter at once.
          If ${lock.holder} is still inside the area, robots may meet there: release only after you have seen it is out.</p>
        <div class="actions">
          <button type="button" class="danger" @click=${release}>Release ${lock.area}</button>
          <button type="button" class="secondary" @click=${close}>Keep the lock</button>
        </div>`
      : ""}
  </dialog>`;
}

export function locksView(ui) {
  const locks = [...ui.store.locks.values()].sort((a, b) => a.area.localeCompare(b.area));
  return html`<h2>Locks</h2>
    <p class="muted">${ui.admin ? "Admins may release any lock." : "Operators may release a lock whose holder is offline."}</p>
    <table>
      <thead><tr><th scope="col">Area</th><th scope="col">State</th><th scope="col">Holder</th><th scope="col">Held for</th><th scope="col">Waiting</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>
        ${locks.map(
          (l) => html`<tr>
            <td>${l.area}</td>
            <td class=${`state-${l.state}`}>${l.state.replace("_", " ")}</td>
            <td>${l.holder ?? "—"}</td>
            <td>${l.since ? duration(Date.now() / 1000 - l.since) : "—"}</td>
            <td>${l.waiting.length ? `${l.waiting.length}: ${l.waiting.join(", ")}` : "nobody"}</td>
            <td>${ui.operate && l.holder && (ui.admin || l.state === "holder_offline")
              ? html`<button type="button" class="danger" @click=${() => confirmRelease(ui, l)}>Force release ${l.area}</button>`
              : ""}</td>
          </tr>`,
        )}
      </tbody>
    </table>
    ${releaseDialog(ui)}`;
}
