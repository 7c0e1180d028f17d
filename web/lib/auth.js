// Who is using the page. People sign in with their account: the server keeps the session in
// an HttpOnly cookie the page never sees, and gives the page a CSRF token to send with every
// change (X-CSRF-Token; docs/security.md "Accounts"). Machines and shared screens use a token:
// staff may still type one (kept in sessionStorage, gone when the tab closes), and a kiosk
// gets its token in the URL fragment (#token=...): fragments never reach the server, so the
// token is not in any access log.

const KEY = "guidebot.token";
let csrf = null;

/** The token from the URL fragment `#token=...`, or null. */
export function fragmentToken() {
  const params = new URLSearchParams(location.hash.slice(1));
  const token = params.get("token");
  return token && token.trim() ? token.trim() : null;
}

/** The signed-in staff token of this tab, or null. */
export function storedToken() {
  return sessionStorage.getItem(KEY);
}

export function saveToken(token) {
  sessionStorage.setItem(KEY, token);
}

export function forgetToken() {
  sessionStorage.removeItem(KEY);
}

/** The token to use: the fragment's (kiosk) first, then this tab's sign-in. */
export function currentToken() {
  return fragmentToken() ?? storedToken();
}

/** Headers a request signed in by the session cookie sends: its CSRF token (for Api's
 * getHeaders; harmless on reads). */
export function sessionHeaders() {
  return csrf ? { "X-CSRF-Token": csrf } : {};
}

async function answer(response) {
  let body = null;
  try {
    body = await response.json();
  } catch {
    body = null;
  }
  return body;
}

/** The session a sign-in answered, or an Error whose message the page can show. */
async function sessionFrom(response) {
  const body = await answer(response);
  if (response.ok) {
    csrf = body.csrf;
    return body;
  }
  if (response.status === 429) {
    const wait = response.headers.get("Retry-After");
    throw new Error(`Too many failed sign-ins: try again in ${wait ?? "a few"} seconds.`);
  }
  if (response.status === 401) throw new Error(typeof body?.detail === "string" && body.detail.includes("passkey") ? "This passkey was not accepted." : "Wrong account name or password.");
  if (response.status === 403) throw new Error("This account is disabled: ask an administrator.");
  if (response.status === 422) throw new Error("Enter your account name and password.");
  throw new Error(`The server answered ${response.status}.`);
}

async function send(path, body, headers = {}) {
  try {
    return await fetch(path, {
      method: "POST",
      headers: { "Content-Type": "application/json", Accept: "application/json", ...headers },
      body: JSON.stringify(body),
    });
  } catch {
    throw new Error("The server cannot be reached: check the network.");
  }
}

/**
 * Sign in with an account name and password. Resolves to the session ({name, display_name,
 * role, csrf, expires_at}) or rejects with an Error whose message the page can show.
 */
export async function signInWithPassword(name, password) {
  return sessionFrom(await send("/api/session", { name, password }));
}

/** Whether this browser can use passkeys here (WebAuthn with its JSON helpers, a secure
 * context: https, or http on localhost). */
export function passkeysAvailable() {
  return typeof window.PublicKeyCredential === "function"
    && typeof PublicKeyCredential.parseRequestOptionsFromJSON === "function"
    && window.isSecureContext;
}

function noPasskey(err) {
  return new Error(err?.name === "NotAllowedError" ? "No passkey was used (cancelled or timed out)." : `The passkey could not be used: ${err?.message ?? err}.`);
}

/** Sign in with a passkey: the authenticator offers the person's passkeys for this server. */
export async function signInWithPasskey() {
  const start = await send("/api/session/passkey/options", {});
  if (!start.ok) return sessionFrom(start);
  const { challenge_id: challengeId, options } = await start.json();
  let credential;
  try {
    credential = await navigator.credentials.get({ publicKey: PublicKeyCredential.parseRequestOptionsFromJSON(options) });
  } catch (err) {
    throw noPasskey(err);
  }
  return sessionFrom(await send("/api/session/passkey", { challenge_id: challengeId, credential: credential.toJSON() }));
}

/** Add a passkey to the signed-in person's account (this device's authenticator). */
export async function addPasskey(label = "") {
  const start = await send("/api/session/passkeys/options", {}, sessionHeaders());
  if (!start.ok) throw new Error(`The server answered ${start.status}.`);
  const { challenge_id: challengeId, options } = await start.json();
  let credential;
  try {
    credential = await navigator.credentials.create({ publicKey: PublicKeyCredential.parseCreationOptionsFromJSON(options) });
  } catch (err) {
    throw noPasskey(err);
  }
  const done = await send("/api/session/passkeys", { challenge_id: challengeId, credential: credential.toJSON(), label }, sessionHeaders());
  const body = await answer(done);
  if (!done.ok) throw new Error(typeof body?.detail === "string" ? body.detail : `The server answered ${done.status}.`);
  return body;
}

let sso = null;

/** The name of the server's single sign-on, or null (known after currentSession()). */
export function singleSignOn() {
  return sso;
}

/** This browser's session (the cookie's), or null when none is live. */
export async function currentSession() {
  try {
    const response = await fetch("/api/session", { headers: { Accept: "application/json" } });
    if (!response.ok) return null;
    const body = await response.json();
    sso = body.sso ?? null;
    if (!body.signed_in) return null;
    csrf = body.csrf;
    return body;
  } catch {
    return null;
  }
}

async function change(method, path) {
  const response = await fetch(path, { method, headers: { Accept: "application/json", ...sessionHeaders() } });
  if (!response.ok && response.status !== 401) throw new Error(`The server answered ${response.status}.`);
  return answer(response);
}

/** End this browser's session (its cookie is cleared). */
export async function signOut() {
  await change("DELETE", "/api/session");
  csrf = null;
}

/** End every session of this account, on every device. */
export async function signOutEverywhere() {
  const ended = await change("POST", "/api/session/everywhere");
  csrf = null;
  return ended;
}
