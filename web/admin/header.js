// The console's header: who is signed in (role, read only for a viewer), sign out, passkeys,
// and which server process serves the page.
import { html, render } from "lit-html";
import { addPasskey, passkeysAvailable } from "/lib/auth.js";
import { venueNow, venueZone } from "/admin/venue.js";

const SERVER_REFRESH_MS = 15000;

/**
 * Draw the header into `who` once, and keep its server line fresh (at every reconnect and
 * every 15 s) until `signal` aborts (the sign-in ended): one timer per sign-in, never one more
 * at each sign-in after a 401.
 * @param {any} ui  the console state (web/admin/console.js)
 * @param {import("/lib/session.js").StaffSession<any>} session
 * @param {HTMLElement} who
 * @param {AbortSignal} signal
 */
export function mountHeader(ui, session, who, signal) {
  const account = session.account;
  render(
    html`<span id="venue-clock"></span>
      <span id="server-status" role="status"></span>
      <span>${account?.display_name || ui.me.name} <span class="badge">${ui.me.role}</span></span>
      ${ui.operate ? "" : html`<span id="read-only">Read only: a viewer watches, changes nothing.</span>`}
      <button type="button" @click=${() => session.signOut(false)}>Sign out</button>
      ${account ? html`<button type="button" class="secondary" @click=${() => session.signOut(true)}>Sign out everywhere</button>` : ""}
      ${account && passkeysAvailable()
        ? html`<button type="button" class="secondary" @click=${() => ui.act("Add a passkey", async () => {
          await addPasskey(navigator.platform || "");
          ui.passkeys = undefined; // "Your passkeys" reads them again
        })}>Add a passkey</button>`
        : ""}
      ${account ? html`<button type="button" class="secondary" @click=${() => ui.go("passkeys")}>Your passkeys</button>` : ""}`,
    who,
  );
  const status = /** @type {HTMLElement} */ (who.querySelector("#server-status"));
  const showServer = () => serverStatus(ui.api).then((view) => {
    if (!signal.aborted) render(view, status);
  });
  showServer();
  ui.hub.addEventListener("connect", showServer);
  const timer = setInterval(showServer, SERVER_REFRESH_MS);
  signal.addEventListener("abort", () => clearInterval(timer), { once: true });
}

/**
 * The venue's clock in the header ("Venue time 14:02 (Europe/Madrid)"): every time the console
 * shows is in that zone (web/admin/venue.js). Started once the zone is known (the site's
 * answer); it turns with the minute until `signal` aborts.
 * @param {HTMLElement} who  the header's part drawn by mountHeader
 * @param {AbortSignal} signal
 */
export function startVenueClock(who, signal) {
  const element = /** @type {HTMLElement | null} */ (who.querySelector("#venue-clock"));
  if (!element) return;
  let timer = 0;
  const tick = () => {
    if (signal.aborted) return;
    render(html`Venue time <time>${venueNow()}</time> <span class="muted-light">(${venueZone()})</span>`, element);
    element.title = `Every time on the console is the venue's (${venueZone()})`;
    timer = window.setTimeout(tick, 60000 - (Date.now() % 60000) + 50);
  };
  tick();
  signal.addEventListener("abort", () => clearTimeout(timer), { once: true });
}

/**
 * The header's server line from /api/health: with several server processes, which one serves
 * this page and which one leads (decides tasks, areas and the building).
 * @param {import("/lib/rest.js").Api} api
 */
async function serverStatus(api) {
  const health = await api.get("/api/health").catch(() => null);
  if (!health) return html`<span class="badge bad">server unreachable</span>`;
  const c = health.cluster;
  const state = html`<span class=${`badge ${health.status === "ok" ? "ok" : "warn"}`}>${health.status}</span>`;
  if (!c) return html`Server ${state}`;
  const leader = c.leader ? `leader ${c.leader} (epoch ${c.epoch})` : "no leader yet";
  return html`Process ${c.process} <span class="badge">${c.leading ? "leads" : "follows"}</span> · ${leader} ${state}`;
}
