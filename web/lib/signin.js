// The sign-in form shared by the console, the site editor and the net editor: a passkey first
// (where the browser can use one), then an account's name and password, then a token
// (kiosks, displays, scripts, the demo's dev tokens). One "Sign in" button for the form: a
// typed token wins, else the account is used.
import { html } from "lit-html";
import { passkeysAvailable } from "/lib/auth.js";

/**
 * @param {{intro: string, tokenLabel?: string, message?: string,
 *          onAccount: (name: string, password: string) => void,
 *          onToken: (token: string) => void, onPasskey?: () => void, sso?: string | null,
 *          back?: string}} options  sso: the single sign-on's name when the server has one;
 *          back: the page to come back to after it
 */
export function signInForm({ intro, tokenLabel = "Staff token", message = "", onAccount, onToken, onPasskey, sso = null, back = location.pathname }) {
  const submit = (event) => {
    event.preventDefault();
    const form = new FormData(event.target);
    const token = String(form.get("token") ?? "").trim();
    const name = String(form.get("name") ?? "").trim();
    const password = String(form.get("password") ?? "");
    if (token) return onToken(token);
    return onAccount(name, password);
  };
  return html`<h2>Sign in</h2>
    <p>${intro}</p>
    ${onPasskey && passkeysAvailable()
      ? html`<p><button type="button" class="passkey" @click=${onPasskey}>Use a passkey</button></p>`
      : ""}
    ${sso
      ? html`<p><button type="button" @click=${() => location.assign(`/api/session/oidc/start?next=${encodeURIComponent(back)}`)}>Use ${sso}</button></p>`
      : ""}
    <form class="signin-form" @submit=${submit}>
      <fieldset>
        <legend>Your account</legend>
        <label>Account name <input name="name" autocomplete="username" autocapitalize="none" spellcheck="false"></label>
        <label>Password <input name="password" type="password" autocomplete="current-password"></label>
      </fieldset>
      <fieldset>
        <legend>Or a token (kiosks, displays, scripts, the demo)</legend>
        <label>${tokenLabel} <input name="token" type="password" autocomplete="off"></label>
      </fieldset>
      <button type="submit">Sign in</button>
    </form>
    ${message ? html`<p class="notice error" role="alert">${message}</p>` : ""}`;
}
