// The sign-in form shared by the console, the site editor and the net editor: a passkey first
// (where the browser can use one), then an account's name and password, then a token
// (kiosks, displays, scripts, the demo's dev tokens). One "Sign in" button for the form: a
// typed token wins, else the account is used.
import { html, render } from "lit-html";
import { passkeysAvailable, saveToken, signInWithPasskey, signInWithPassword, singleSignOn } from "/lib/auth.js";

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

const SSO_REFUSED = {
  refused: () => "Single sign-on refused: the answer did not match this sign-in, or it took too long. Start again.",
  provider: (sso) => `${sso} did not sign you in (cancelled or refused there). Try again, or sign in another way.`,
  no_role: (sso) => `${sso}: none of your groups has a GuideBot role: ask an administrator.`,
  disabled: () => "This account is disabled: ask an administrator.",
  locked: (_sso, retry) => `Too many failed sign-ins: try again in ${retry ?? "a few"} seconds.`,
  unreachable: (sso) => `${sso} cannot be reached: try again later, or sign in another way.`,
};

/**
 * Why the server sent the browser back from a single sign-on (`#sso_refused=<code>`, with
 * `&retry=<s>` when locked), in words; the fragment is taken off the address so a reload does
 * not say it again. "" without one. Only codes are read: a crafted link cannot put its own
 * words on the form.
 */
export function ssoRefusal() {
  const params = new URLSearchParams(location.hash.slice(1));
  const code = params.get("sso_refused");
  if (code === null) return "";
  history.replaceState(null, "", location.pathname + location.search);
  const say = SSO_REFUSED[code] ?? SSO_REFUSED.refused;
  const retry = params.get("retry");
  return say(singleSignOn() ?? "Single sign-on", /^\d{1,5}$/.test(retry ?? "") ? retry : null);
}

/**
 * Show the sign-in form in `section` and sign in from it, the same way on every staff page:
 * a typed token is checked before this tab keeps it; an account (password or passkey) opens
 * a session cookie, then the page checks whom it serves.
 * @param {{section: HTMLElement, intro: string, tokenLabel?: string, message?: string,
 *          missing: string, useToken: (token: string | null) => void,
 *          check: () => Promise<any>, done: (known: any) => void,
 *          again: (message: string) => void}} options
 *   missing: what to say when the name or password is left out; useToken: the page's token
 *   (null: the session cookie); check: whom the page serves, or an Error saying why not;
 *   done: the page starts with what check answered; again: the page shows the form again
 *   with a message (its own showSignIn). Without a message, a refused single sign-on's.
 */
export function signInFlow({ section, intro, tokenLabel, message = "", missing, useToken, check, done, again }) {
  const onToken = async (value) => {
    useToken(value);
    const known = await check();
    if (known instanceof Error) {
      useToken(null);
      return again(known.message);
    }
    saveToken(value);
    return done(known);
  };
  const signedIn = async (how) => {
    try {
      await how();
    } catch (err) {
      return again(err.message);
    }
    useToken(null);
    const known = await check();
    if (known instanceof Error) return again(known.message);
    return done(known);
  };
  const onAccount = async (name, password) => {
    if (!name || !password) return again(missing);
    return signedIn(() => signInWithPassword(name, password));
  };
  render(signInForm({
    intro,
    tokenLabel,
    message: message || ssoRefusal(),
    onAccount,
    onToken,
    onPasskey: () => signedIn(signInWithPasskey),
    sso: singleSignOn(),
  }), section);
  section.querySelector("input").focus();
}
