// Notifications: staff told of alerts outside this tab, by e-mail (the venue's SMTP server) and
// signed webhooks (a chat tool). Admins set the SMTP server and the channels with their rules
// (severities, days and hours, quiet hours, repeat) and send a test; every staff member reads the
// delivery log with its failures (docs/console.md "Notifications", docs/server.md).
// Secrets are write-only: the server says whether one is set, never what it is.
import { html } from "lit-html";
import { clock, venueZone } from "/admin/venue.js";

const DAYS = [["mon", "Mon"], ["tue", "Tue"], ["wed", "Wed"], ["thu", "Thu"], ["fri", "Fri"], ["sat", "Sat"], ["sun", "Sun"]];
const SEVERITIES = ["warning", "error"];
const STATUS_CLASS = { sent: "ok", suppressed: "", queued: "warn", sending: "warn", retrying: "warn", failed: "bad", dropped: "bad" };

/** A refusal as the person reads it: each field named ("to: not an e-mail address"). */
function why(err) {
  if (!Array.isArray(err.detail)) return err.message;
  return err.detail
    .map((d) => {
      const where = (d.loc ?? []).filter((p) => p !== "body" && p !== "email" && p !== "webhook").join(".");
      return where ? `${where}: ${d.msg}` : d.msg;
    })
    .join("; ");
}

async function reload(ui) {
  const state = ui.notify;
  const [settings, log] = await Promise.all([
    ui.admin ? ui.api.get("/api/notifications") : Promise.resolve(null),
    ui.api.get("/api/notifications/deliveries"),
  ]);
  state.settings = settings;
  state.log = log;
  ui.draw();
}

/** Run a change; a refusal is shown with the fields it names. */
function change(ui, label, fn, after = () => {}) {
  ui.act(label, async () => {
    try {
      await fn();
    } catch (err) {
      throw new Error(why(err));
    }
    after();
    await reload(ui);
  });
}

const timeOf = (value) => (value === "24:00" ? "00:00" : value);
const endOf = (value) => (value === "00:00" ? "24:00" : value);

function smtpForm(ui) {
  const smtp = ui.notify.settings?.smtp;
  const submit = (event) => {
    event.preventDefault();
    const data = new FormData(event.target);
    const body = {
      host: String(data.get("host")).trim(),
      port: Number(data.get("port")),
      security: String(data.get("security")),
      sender: String(data.get("sender")).trim(),
    };
    const user = String(data.get("username")).trim();
    const password = String(data.get("password"));
    if (user) body.username = user;
    if (password) body.password = password;
    change(ui, "Save the SMTP server", () => ui.api.put("/api/notifications/smtp", body));
  };
  return html`<form class="inline" aria-labelledby="smtp-title" @submit=${submit}>
    <h3 id="smtp-title">SMTP server</h3>
    <label>Host <input name="host" required autocomplete="off" spellcheck="false" .value=${smtp?.host ?? ""}></label>
    <label>Port <input name="port" type="number" min="1" max="65535" required .value=${String(smtp?.port ?? 587)}></label>
    <label>Security <select name="security">
      ${[["starttls", "STARTTLS (587)"], ["tls", "TLS (465)"], ["none", "none (a relay on this machine)"]].map(
        ([v, text]) => html`<option value=${v} ?selected=${(smtp?.security ?? "starttls") === v}>${text}</option>`,
      )}</select></label>
    <label>User <input name="username" autocomplete="off" spellcheck="false" .value=${smtp?.username ?? ""}></label>
    <label>Password <input name="password" type="password" autocomplete="new-password"
      placeholder=${smtp?.password_set ? "unchanged (set)" : ""}></label>
    <label>From address <input name="sender" type="email" required autocomplete="off" .value=${smtp?.sender ?? ""}></label>
    <button type="submit">Save SMTP server</button>
  </form>`;
}

function channelBody(form, kind) {
  const data = new FormData(form);
  const window = (start, end) => ({ start: String(data.get(start)), end: endOf(String(data.get(end))) });
  const repeat = String(data.get("repeat")).trim();
  const body = {
    kind,
    name: String(data.get("name")).trim(),
    enabled: data.get("enabled") === "on",
    severities: data.getAll("severities").map(String),
    days: data.getAll("days").map(String),
    hours: window("hours_start", "hours_end"),
    quiet: data.get("quiet") === "on" ? window("quiet_start", "quiet_end") : null,
    timezone: String(data.get("timezone")).trim(),
    repeat_minutes: repeat ? Number(repeat) : null,
  };
  if (kind === "email") body.to = String(data.get("to")).trim();
  else {
    body.url = String(data.get("url")).trim();
    const secret = String(data.get("secret"));
    if (secret) body.secret = secret;
  }
  return body;
}

function channelForm(ui) {
  const state = ui.notify;
  const old = state.editing === "new" ? null : state.settings.channels.find((c) => c.id === state.editing);
  const kind = old?.kind ?? state.kind;
  const zone = venueZone(); // a new channel's hours are the venue's, as every time here
  const c = old ?? {
    name: "", enabled: true, severities: [...SEVERITIES], days: DAYS.map(([d]) => d),
    hours: { start: "00:00", end: "24:00" }, quiet: null, timezone: zone, repeat_minutes: null,
  };
  const done = () => { state.editing = null; };
  const submit = (event) => {
    event.preventDefault();
    const body = channelBody(event.target, kind);
    if (old) {
      change(ui, `Save channel ${body.name}`, () => ui.api.put(`/api/notifications/channels/${encodeURIComponent(old.id)}`, body), done);
    } else {
      change(ui, `Add channel ${body.name}`, () => ui.api.post("/api/notifications/channels", body), done);
    }
  };
  const pickKind = (event) => { state.kind = event.target.value; ui.draw(); };
  return html`<form aria-labelledby="channel-title" @submit=${submit}>
    <h3 id="channel-title">${old ? `Channel ${old.name}` : "New channel"}</h3>
    <div class="inline">
      ${old ? "" : html`<label>Kind <select name="kind" @change=${pickKind}>
        <option value="email" ?selected=${kind === "email"}>e-mail</option>
        <option value="webhook" ?selected=${kind === "webhook"}>webhook</option></select></label>`}
      <label>Name <input name="name" required maxlength="64" autocomplete="off" .value=${c.name}></label>
      ${kind === "email"
        ? html`<label>E-mail address <input name="to" type="email" required autocomplete="off" .value=${c.to ?? ""}></label>`
        : html`<label>Webhook URL <input name="url" type="url" required autocomplete="off" spellcheck="false" .value=${c.url ?? ""}></label>
          <label>Shared secret <input name="secret" type="password" autocomplete="new-password" minlength="16" ?required=${!old}
            placeholder=${old?.secret_set ? "unchanged (set)" : "16 characters or more"}></label>`}
      <label><input type="checkbox" name="enabled" ?checked=${c.enabled}> Enabled</label>
    </div>
    <fieldset class="inline"><legend>Severities</legend>
      ${SEVERITIES.map((s) => html`<label><input type="checkbox" name="severities" value=${s} ?checked=${c.severities.includes(s)}> ${s}</label>`)}
    </fieldset>
    <fieldset class="inline"><legend>When</legend>
      ${DAYS.map(([d, text]) => html`<label><input type="checkbox" name="days" value=${d} ?checked=${c.days.includes(d)}> ${text}</label>`)}
      <label>From <input type="time" name="hours_start" required .value=${timeOf(c.hours.start)}></label>
      <label>Until <input type="time" name="hours_end" required .value=${timeOf(c.hours.end)}></label>
      <label>Time zone <input name="timezone" required autocomplete="off" spellcheck="false" .value=${c.timezone}></label>
    </fieldset>
    <fieldset class="inline"><legend>Quiet hours</legend>
      <label><input type="checkbox" name="quiet" ?checked=${Boolean(c.quiet)}> Quiet hours on</label>
      <label>Quiet from <input type="time" name="quiet_start" .value=${timeOf(c.quiet?.start ?? "22:00")}></label>
      <label>Quiet until <input type="time" name="quiet_end" .value=${timeOf(c.quiet?.end ?? "07:00")}></label>
    </fieldset>
    <div class="inline">
      <label>Repeat every (minutes, empty: once) <input name="repeat" type="number" min="1" max="1440" .value=${c.repeat_minutes == null ? "" : String(c.repeat_minutes)}></label>
      <button type="submit">Save channel</button>
      <button type="button" class="secondary" @click=${() => { done(); ui.draw(); }}>Cancel</button>
    </div>
  </form>`;
}

function when(c) {
  const days = c.days.length === 7 ? "every day" : c.days.join(", ");
  const hours = c.hours.start === "00:00" && c.hours.end === "24:00" ? "all day" : `${c.hours.start}–${c.hours.end}`;
  const quiet = c.quiet ? `, quiet ${c.quiet.start}–${c.quiet.end}` : "";
  return `${days}, ${hours}${quiet} (${c.timezone})`;
}

function channelRow(ui, c) {
  const path = `/api/notifications/channels/${encodeURIComponent(c.id)}`;
  const test = () =>
    ui.act(`Send test to ${c.name}`, async () => {
      const delivery = await ui.api.post(`${path}/test`);
      await reload(ui);
      if (delivery.status !== "sent") throw new Error(`not delivered (${delivery.status}): ${delivery.error}`);
    });
  const remove = () => change(ui, `Delete channel ${c.name}`, () => ui.api.delete(path));
  return html`<tr data-channel=${c.id}>
    <td>${c.name}</td>
    <td>${c.kind === "email" ? "e-mail" : "webhook"}</td>
    <td class="wrap">${c.kind === "email" ? c.to : c.url}</td>
    <td>${c.severities.join(", ")}</td>
    <td>${when(c)}</td>
    <td>${c.repeat_minutes ? `every ${c.repeat_minutes} min` : "once"}</td>
    <td>${c.enabled ? "enabled" : html`<span class="muted">disabled</span>`}</td>
    <td>
      <button type="button" @click=${test}>Send test <span class="sr-only">to ${c.name}</span></button>
      <button type="button" class="secondary" @click=${() => { ui.notify.editing = c.id; ui.draw(); }}>Edit <span class="sr-only">${c.name}</span></button>
      <button type="button" class="danger" @click=${remove}>Delete <span class="sr-only">${c.name}</span></button>
    </td>
  </tr>`;
}

function logTable(ui) {
  const log = ui.notify.log ?? [];
  return html`<h3 id="log-title">Delivery log</h3>
    <button type="button" class="secondary" @click=${() => ui.act("Refresh the delivery log", () => reload(ui))}>Refresh the log</button>
    <table aria-labelledby="log-title">
      <thead><tr><th scope="col">Time</th><th scope="col">Channel</th><th scope="col">Alert</th><th scope="col">Why</th>
        <th scope="col">Status</th><th scope="col">Attempts</th><th scope="col">Error or answer</th></tr></thead>
      <tbody>${log.map(
        (d) => html`<tr data-delivery=${d.id} data-status=${d.status}>
          <td>${clock(d.created_at)}</td>
          <td>${d.channel_name} <span class="muted">(${d.kind})</span></td>
          <td>${d.alert}</td>
          <td>${d.reason}</td>
          <td><span class=${`badge ${STATUS_CLASS[d.status] ?? ""}`}>${d.status}</span>${d.next_attempt_at ? html` <span class="muted">next ${clock(d.next_attempt_at)}</span>` : ""}</td>
          <td>${d.attempts}</td>
          <td class="wrap">${d.error || d.result}</td>
        </tr>`,
      )}</tbody>
    </table>
    ${log.length ? "" : html`<p class="muted">Nothing sent yet.</p>`}`;
}

export function notificationsView(ui) {
  if (ui.notify === undefined) {
    ui.notify = { settings: null, log: null, editing: null, kind: "email" };
    reload(ui).catch((err) => {
      ui.notice = { ok: false, text: `Notifications: ${err.message}` };
      ui.notify.log = [];
      ui.draw();
    });
  }
  const state = ui.notify;
  const channels = state.settings?.channels ?? [];
  const settings = ui.admin && state.settings
    ? html`${smtpForm(ui)}
      <h3 id="channels-title">Channels</h3>
      <table aria-labelledby="channels-title">
        <thead><tr><th scope="col">Name</th><th scope="col">Kind</th><th scope="col">To</th><th scope="col">Severities</th>
          <th scope="col">When</th><th scope="col">Repeat</th><th scope="col">State</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
        <tbody>${channels.map((c) => channelRow(ui, c))}</tbody>
      </table>
      ${channels.length ? "" : html`<p class="muted">No channel yet: nobody is told outside this console.</p>`}
      ${state.editing ? channelForm(ui) : html`<button type="button" @click=${() => { state.editing = "new"; ui.draw(); }}>Add a channel</button>`}`
    : html`<p class="muted">Admins set who is told and when; the log shows what was sent.</p>`;
  return html`<h2>Notifications</h2>
    <p class="muted">Alerts reach staff outside this tab: by e-mail and by webhook (a chat tool), when each
      channel's rules say so. A failed delivery is retried, then shown here and raised as an alert.</p>
    ${state.log === null ? html`<p role="status">Loading notifications…</p>` : ""}
    ${settings}
    ${logTable(ui)}`;
}
