// Alerts: the bar shown on every view while alerts are open, and the Alerts view. One row per
// cause (kind and subject): seen again it counts; it resolves itself when its cause is gone.
import { html } from "lit-html";
import { clock } from "/admin/venue.js";

function ack(ui, alert) {
  return ui.act(`Acknowledge ${alert.kind}`, () => ui.api.post(`/api/alerts/${encodeURIComponent(alert.id)}/ack`));
}

function ackAll(ui) {
  return ui.act("Acknowledge all alerts", () => ui.api.post("/api/alerts/ack-all"));
}

const times = (a) => (a.count > 1 ? ` (${a.count} times, last at ${clock(a.last_seen)})` : "");

function state(a) {
  const acked = a.acked_at ? `acknowledged by ${a.acked_by} at ${clock(a.acked_at)}` : "";
  if (a.resolved_at) {
    return html`<span class="badge ok">resolved</span> ${clock(a.resolved_at)}${a.resolution ? `: ${a.resolution}` : ""}${acked ? html`<br>${acked}` : ""}`;
  }
  return acked || html`<span class="badge bad">open</span>`;
}

/** Open ones first, then acknowledged ones still active, then resolved; last seen first. */
function rank(a) {
  if (a.resolved_at) return 2;
  return a.acked_at ? 1 : 0;
}

export function alertBar(ui, open) {
  if (!open.length) return "";
  const latest = open[0];
  const text = `${open.length} open alert${open.length > 1 ? "s" : ""}: ${latest.message}${times(latest)}`;
  return html`<span class="alert-text" title=${text}>${text}</span>
    ${ui.operate ? html`<button type="button" class="danger" @click=${() => ack(ui, latest)}>Acknowledge</button>` : ""}
    ${ui.operate && open.length > 1 ? html`<button type="button" class="danger" @click=${() => ackAll(ui)}>Acknowledge all</button>` : ""}
    <button type="button" class="secondary" @click=${() => ui.go("alerts")}>All alerts</button>`;
}

export function alertsView(ui) {
  const all = [...ui.store.alerts.values()].sort((a, b) => rank(a) - rank(b) || b.last_seen - a.last_seen);
  const open = all.filter((a) => rank(a) === 0).length;
  return html`<h2>Alerts</h2>
    <label><input type="checkbox" .checked=${ui.sound} @change=${(e) => { ui.sound = e.target.checked; }}> Sound on new alerts</label>
    ${ui.operate ? html`<button type="button" ?disabled=${!open} @click=${() => ackAll(ui)}>Acknowledge all${open ? ` (${open})` : ""}</button>` : ""}
    <table>
      <thead><tr><th scope="col">Raised</th><th scope="col">Severity</th><th scope="col">What</th><th scope="col">State</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>
        ${all.map(
          (a) => html`<tr data-alert=${a.id} data-state=${["open", "acknowledged", "resolved"][rank(a)]} class=${a.resolved_at ? "muted" : ""}>
            <td>${clock(a.raised_at)}</td>
            <td><span class=${`badge ${a.severity === "error" ? "bad" : "warn"}`}>${a.severity}</span></td>
            <td>${a.message}${times(a)}</td>
            <td>${state(a)}</td>
            <td>${rank(a) === 0 && ui.operate ? html`<button type="button" @click=${() => ack(ui, a)}>Acknowledge <span class="sr-only">${a.message}</span></button>` : ""}</td>
          </tr>`,
        )}
      </tbody>
    </table>
    ${all.length ? "" : html`<p class="muted">No alerts.</p>`}`;
}
