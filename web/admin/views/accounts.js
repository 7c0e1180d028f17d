// Accounts (admins): people who sign in, their roles, last sign-in, passkeys; create, change
// the role, disable or enable, set a new password, remove a person's passkeys (a lost phone).
// Changing a role, disabling, a new password and removing the passkeys end the person's
// sessions at once, on every page and hub link (docs/security.md "Accounts").
// Your passkeys (anyone signed in with an account): list them, remove one.
import { html } from "lit-html";
import { confirmAction } from "/lib/confirm.js";
import { dateTime } from "/admin/venue.js";

const ROLES = [
  ["admin", "admin: everything, accounts too"],
  ["operator", "operator: the console"],
  ["installer", "installer: the site editor"],
  ["author", "author: the net editor"],
  ["viewer", "viewer: reads only"],
];

function when(at) {
  return at ? dateTime(at) : "never";
}

async function reload(ui) {
  ui.accounts = (await ui.api.get("/api/accounts")).accounts;
  ui.draw();
}

function change(ui, label, fn) {
  ui.act(label, async () => {
    await fn();
    await reload(ui);
  });
}

function createForm(ui) {
  const submit = (event) => {
    event.preventDefault();
    const form = event.target;
    const data = new FormData(form);
    const body = {
      name: String(data.get("name")).trim(),
      display_name: String(data.get("display_name")).trim(),
      role: String(data.get("role")),
      password: String(data.get("password")),
    };
    change(ui, `Create account ${body.name}`, async () => {
      await ui.api.post("/api/accounts", body);
      form.reset();
    });
  };
  return html`<form class="inline" aria-labelledby="new-account" @submit=${submit}>
    <h3 id="new-account">New account</h3>
    <label>Account name <input name="name" required autocomplete="off" autocapitalize="none" spellcheck="false"
      pattern="[a-z][a-z0-9._\\-]{1,31}" title="2 to 32 lowercase letters, digits, '.', '-' or '_', starting with a letter"></label>
    <label>Display name <input name="display_name" autocomplete="off"></label>
    <label>Role <select name="role">${ROLES.map(([r, text]) => html`<option value=${r} ?selected=${r === "operator"}>${text}</option>`)}</select></label>
    <label>First password <input name="password" type="password" required minlength="12" autocomplete="new-password"></label>
    <button type="submit">Create account</button>
  </form>`;
}

function passwordForm(ui, account) {
  const submit = (event) => {
    event.preventDefault();
    const password = String(new FormData(event.target).get("password"));
    ui.resetting = null;
    change(ui, `New password for ${account.name}`, () =>
      ui.api.post(`/api/accounts/${encodeURIComponent(account.name)}/password`, { password }));
  };
  return html`<form class="inline" @submit=${submit}>
    <label>New password for ${account.name} <input name="password" type="password" required minlength="12" autocomplete="new-password"></label>
    <button type="submit">Set password</button>
    <button type="button" class="secondary" @click=${() => { ui.resetting = null; ui.draw(); }}>Cancel</button>
  </form>`;
}

function row(ui, a) {
  const path = `/api/accounts/${encodeURIComponent(a.name)}`;
  const setRole = (event) =>
    change(ui, `Role of ${a.name}`, () => ui.api.put(path, { role: event.target.value }));
  const toggle = () =>
    change(ui, `${a.disabled ? "Enable" : "Disable"} ${a.name}`, () => ui.api.put(path, { disabled: !a.disabled }));
  return html`<tr>
    <td>${a.name}</td>
    <td>${a.display_name || "—"}</td>
    <td><label><span class="sr-only">Role of ${a.name}</span>
      <select @change=${setRole}>${ROLES.map(([r]) => html`<option value=${r} ?selected=${a.role === r}>${r}</option>`)}</select></label></td>
    <td class=${a.disabled ? "state-disabled" : ""}>${a.disabled ? "disabled" : "enabled"}</td>
    <td>${when(a.last_sign_in)}</td>
    <td>${a.passkeys ?? 0}</td>
    <td>
      <button type="button" class=${a.disabled ? "secondary" : "danger"} @click=${toggle}>${a.disabled ? "Enable" : "Disable"} ${a.name}</button>
      <button type="button" class="secondary" @click=${() => { ui.resetting = a.name; ui.draw(); }}>New password for ${a.name}</button>
      ${a.passkeys ? html`<button type="button" class="danger" @click=${() => removePasskeys(ui, a)}>Remove passkeys of ${a.name}</button>` : ""}
    </td>
  </tr>`;
}

async function removePasskeys(ui, account) {
  const ok = await confirmAction({
    title: `Remove the passkeys of ${account.name}?`,
    text: `All ${account.passkeys} passkey(s) of ${account.name} stop working and ${account.name} is signed out everywhere (a lost phone or laptop). They sign in with their password and add a passkey again.`,
    confirm: "Remove passkeys",
    keep: "Keep them",
  });
  if (!ok) return;
  change(ui, `Remove passkeys of ${account.name}`, () =>
    ui.api.delete(`/api/accounts/${encodeURIComponent(account.name)}/passkeys`));
}

function passkeyName(key) {
  return key.label || `passkey ${key.id.slice(0, 6)}`;
}

/** The signed-in person's passkeys: name, added, last used; remove one (a device given away). */
export function passkeysView(ui) {
  const load = () => ui.api.get("/api/session/passkeys").then(({ passkeys }) => {
    ui.passkeys = passkeys;
    ui.draw();
  }).catch((err) => {
    ui.passkeys = [];
    ui.notice = { ok: false, text: `Your passkeys: ${err.message}` };
    ui.draw();
  });
  if (ui.passkeys === undefined) {
    ui.passkeys = null;
    load();
  }
  const keys = ui.passkeys ?? [];
  const remove = (key) => ui.act(`Remove ${passkeyName(key)}`, async () => {
    await ui.api.delete(`/api/session/passkeys/${encodeURIComponent(key.id)}`);
    await load();
  });
  return html`<h2>Your passkeys</h2>
    <p class="muted">Each passkey signs you in from one device without a password. Remove the one of a
      device you no longer use; your other passkeys and your password stay.</p>
    ${ui.passkeys === null ? html`<p role="status">Loading passkeys…</p>` : ""}
    <table aria-label="Your passkeys">
      <thead><tr><th scope="col">Name</th><th scope="col">Added</th><th scope="col">Last used</th>
        <th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${ui.passkeys !== null && !keys.length ? html`<tr><td colspan="4">No passkey yet.</td></tr>` : ""}
        ${keys.map((key) => html`<tr>
          <td>${passkeyName(key)}</td><td>${when(key.created_at)}</td><td>${when(key.last_used)}</td>
          <td><button type="button" class="danger" @click=${() => remove(key)}>Remove ${passkeyName(key)}</button></td>
        </tr>`)}</tbody>
    </table>`;
}

export function accountsView(ui) {
  if (ui.accounts === undefined) {
    ui.accounts = null;
    reload(ui).catch((err) => {
      ui.notice = { ok: false, text: `Accounts: ${err.message}` };
      ui.accounts = [];
      ui.draw();
    });
  }
  const accounts = ui.accounts ?? [];
  const resetting = accounts.find((a) => a.name === ui.resetting);
  return html`<h2>Accounts</h2>
    <p class="muted">People who sign in with their own name. Changing a role, disabling an account,
      setting a new password or removing the person's passkeys signs the person out at once, on every page.</p>
    ${ui.accounts === null ? html`<p role="status">Loading accounts…</p>` : ""}
    <table aria-label="Accounts">
      <thead><tr><th scope="col">Name</th><th scope="col">Display name</th><th scope="col">Role</th>
        <th scope="col">State</th><th scope="col">Last sign-in</th><th scope="col">Passkeys</th>
        <th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${ui.accounts !== null && !accounts.length
        ? html`<tr><td colspan="7">No account yet: create the first below.</td></tr>`
        : accounts.map((a) => row(ui, a))}</tbody>
    </table>
    ${resetting ? passwordForm(ui, resetting) : ""}
    ${createForm(ui)}`;
}
