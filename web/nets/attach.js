// Attach the RoboGraph editor to a running net (docs/nets.md, "Attach"): a robot's (or the
// server's) running instances, the live marking from the hub's petri_net_event (as the
// console's monitor follows it), breakpoints that pause the instance before a transition,
// step, resume and kill. Breakpoints are leased: the page renews them while attached and
// clears them when it detaches or closes; a page that dies stops renewing and they go.
import { html, nothing } from "lit-html";
import { sessionHeaders } from "/lib/auth.js";
import { HubClient } from "/lib/hub.js";

const LEASE_S = 120; // in the dispatch's clock: a robot's runs faster in simulation
const RENEW_MS = 5000;

export class Attachment {
  constructor(api, token, changed) {
    this.api = api;
    this.token = token;
    this.changed = changed;
    this.target = "";
    this.targets = [];
    this.instances = null; // the running nets of `target`, once asked
    this.instance = null; // {instance_id, net}
    this.marking = new Map();
    this.pausedAt = null;
    this.last = [];
    this.breakpoints = new Set();
    this.ended = null;
    /** @type {HubClient | null} */
    this.hub = null;
    this.off = null;
    this.renew = null;
    addEventListener("pagehide", () => this.#clear(true));
  }

  async loadTargets() {
    const robots = await this.api.get("/api/robots");
    this.targets = [...robots.map((r) => r.name), "rgm"];
    this.target ||= this.targets[0] ?? "rgm";
  }

  async list() {
    this.instances = await this.api.get(`/api/nets/running?target=${encodeURIComponent(this.target)}`);
    this.changed();
  }

  /** Follow one instance: its marking now, then live from the hub. */
  async attach(item) {
    await this.detach();
    this.instance = { instance_id: item.instance_id, net: item.net, target: this.target };
    this.marking = new Map(Object.entries(item.marking));
    this.pausedAt = item.paused_at ?? null;
    this.last = this.pausedAt ? [this.pausedAt] : [];
    this.ended = null;
    this.breakpoints = new Set();
    if (!this.hub) this.hub = new HubClient({ token: this.token }).start();
    this.off = this.hub.on("petri_net_event", (m) => this.#event(m));
    this.hub.subscribe("petri_net_event");
    this.renew = setInterval(() => { if (this.breakpoints.size) this.#send("break").catch(() => {}); }, RENEW_MS);
  }

  async detach() {
    if (!this.instance) return;
    await this.#clear(false);
    clearInterval(this.renew);
    this.off?.();
    this.hub?.unsubscribe("petri_net_event");
    this.instance = null;
    this.pausedAt = null;
    this.last = [];
  }

  /** @param {import("/lib/messages.js").Message<"petri_net_event">} m */
  #event(m) {
    const inst = this.instance;
    const p = m.payload;
    if (!inst || (m.source || "rgm") !== inst.target || p.instance_id !== inst.instance_id) return;
    if (p.kind === "ended") {
      this.ended = p;
      this.pausedAt = null;
      clearInterval(this.renew);
    } else {
      if (p.kind === "started" || p.kind === "paused") this.marking = new Map(Object.entries(p.marking));
      else for (const [place, n] of Object.entries(p.marking)) this.marking.set(place, n);
      this.pausedAt = p.kind === "paused" ? p.transition : null;
      this.last = p.transitions ?? (p.transition ? [p.transition] : []);
    }
    this.changed();
  }

  #body(command) {
    const inst = this.instance;
    return { target: inst.target, instance_id: inst.instance_id, command, breakpoints: [...this.breakpoints], lease_s: LEASE_S };
  }

  #send(command) {
    return this.api.post("/api/net-editor/debug", this.#body(command));
  }

  /** Breakpoints off (on detach, or as the page goes: a request that outlives the page). */
  async #clear(leaving) {
    if (!this.instance || !this.breakpoints.size || this.ended) return;
    this.breakpoints = new Set();
    const body = JSON.stringify(this.#body("break"));
    const auth = this.token ? { Authorization: `Bearer ${this.token}` } : sessionHeaders();
    const headers = { ...auth, "Content-Type": "application/json" };
    if (leaving) fetch("/api/net-editor/debug", { method: "POST", body, headers, keepalive: true });
    else await this.api.post("/api/net-editor/debug", JSON.parse(body)).catch(() => {});
  }

  async toggle(transition) {
    if (this.breakpoints.has(transition)) this.breakpoints.delete(transition);
    else this.breakpoints.add(transition);
    await this.#send("break");
    this.changed();
  }

  step() { return this.#send("step"); }
  resume() { return this.#send("resume"); }

  kill() {
    const inst = this.instance;
    return this.api.post("/api/nets/kill", { target: inst.target, instance_id: inst.instance_id });
  }
}

/** The panel: choose a robot and one of its running nets; then its state and the controls. */
export function attachPanel(ui, a, actions) {
  const inst = a.instance;
  const doc = ui.model.doc;
  const status = !inst ? "" : a.ended ? `${inst.instance_id} ended.`
    : a.pausedAt ? `${inst.instance_id} is paused before ${a.pausedAt}.` : `${inst.instance_id} is running${a.last.length ? `: last fired ${a.last.join(", ")}` : ""}.`;
  return html`<section aria-labelledby="attach-title"><h2 id="attach-title">Attach to a running net</h2>
    <div class="bar">
      <label>Robot <select @change=${(e) => { a.target = e.target.value; a.instances = null; ui.draw(); }}>
        ${a.targets.map((t) => html`<option value=${t} ?selected=${t === a.target}>${t === "rgm" ? "the server (rgm)" : t}</option>`)}</select></label>
      <button type="button" class="secondary" @click=${actions.list}>Show running nets</button>
    </div>
    ${a.instances ? a.instances.length ? html`<ul class="elements" aria-label=${`Nets running on ${a.target}`}>${a.instances.map((n) => html`<li>
        <button type="button" class="element" @click=${() => actions.attach(n)}>Attach to ${n.instance_id}</button></li>`)}</ul>`
      : html`<p class="muted">No net runs on ${a.target}.</p>` : nothing}
    ${inst ? html`
      <p id="attach-status" role="status">${status}</p>
      ${a.ended ? nothing : html`
        ${ui.mayDebug && doc && doc.id === inst.net ? html`<fieldset class="breakpoints"><legend>Breakpoints: pause before</legend>
          ${doc.transitions.map((t) => html`<label><input type="checkbox" .checked=${a.breakpoints.has(t.id)} @change=${() => actions.toggle(t.id)}> ${t.id}</label>`)}</fieldset>` : nothing}
        <div class="bar">
          ${ui.mayDebug ? html`<button type="button" ?disabled=${!a.pausedAt} @click=${actions.step}>Step</button>
            <button type="button" ?disabled=${!a.pausedAt} @click=${actions.resume}>Resume</button>` : nothing}
          ${ui.me.role === "admin" ? html`<button type="button" class="danger" @click=${actions.kill}>Kill ${inst.instance_id}</button>` : nothing}
        </div>`}
      <button type="button" class="secondary" @click=${actions.detach}>Detach</button>` : nothing}
  </section>`;
}
