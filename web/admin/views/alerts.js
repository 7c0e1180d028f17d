// Alerts: the bar shown on every view while alerts are open, and the Alerts view.
import { html } from "lit-html";
import { clock } from "/lib/dom.js";

function ack(ui, alert) {
  return ui.act(`Acknowledge ${alert.kind}`, () => ui.api.post(`/api/alerts/${encodeURIComponent(alert.id)}/ack`));
}

export function alertBar(ui, open) {
  if (!open.length) return "";
  const latest = open[0];
  return html`<span>${open.length} open alert${open.length > 1 ? "s" : ""}: ${latest.message}</span>
    <button type="button" class="danger" @click=${() => ack(ui, latest)}>Acknowledge</button>
    <button type="button" class="secondary" @click=${() => ui.go("alerts")}>All alerts</button>`;
}

export function alertsView(ui) {
  const all = [...ui.store.alerts.values()].sort((a, b) => b.raised_at - a.raised_at);
  return html`<h2>Alerts</h2>
    <label><input type="checkbox" .checked=${ui.sound} @change=${(e) => { ui.sound = e.target.checked; }}> Sound on new alerts</label>
    <table>
      <thead><tr><th scope="col">Raised</th><th scope="col">Severity</th><th scope="col">What</th><th scope="col">Acknowledged</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>
        ${all.map(
          (a) => html`<tr>
            <td>${clock(a.raised_at)}</td>
            <td><span class=${`badge ${a.severity === "error" ? "bad" : "warn"}`}>${a.severity}</span></td>
            <td>${a.message}</td>
            <td>${a.acked_at ? `by ${a.acked_by} at ${clock(a.acked_at)}` : "open"}</td>
            <td>${a.acked_at ? "" : html`<button type="button" @click=${() => ack(ui, a)}>Acknowledge <span class="sr-only">${a.message}</span></button>`}</td>
          </tr>`,
        )}
      </tbody>
    </table>
    ${all.length ? "" : html`<p class="muted">No alerts.</p>`}`;
}
