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

/**
 * Sign in with an account name and password. Resolves to the session ({name, display_name,
 * role, csrf, expires_at}) or rejects with an Error whose message the page can show.
 */
export async function signInWithPassword(name, password) {
  let response;
  try {
    response = await fetch("/api/session", {
      method: "POST",
      headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify({ name, password }),
    });
  } catch {
    throw new Error("The server cannot be reached: check the network.");
  }
  const body = await answer(response);
  if (response.ok) {
    csrf = body.csrf;
    return body;
  }
  if (response.status === 429) {
    const wait = response.headers.get("Retry-After");
    throw new Error(`Too many failed sign-ins: try again in ${wait ?? "a few"} seconds.`);
  }
  if (response.status === 401) throw new Error("Wrong account name or password.");
  if (response.status === 403) throw new Error("This account is disabled: ask an administrator.");
  if (response.status === 422) throw new Error("Enter your account name and password.");
  throw new Error(`The server answered ${response.status}.`);
}

/** This browser's session (the cookie's), or null when none is live. */
export async function currentSession() {
  try {
    const response = await fetch("/api/session", { headers: { Accept: "application/json" } });
    if (!response.ok) return null;
    const body = await response.json();
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
