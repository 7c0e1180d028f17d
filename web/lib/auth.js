// Who is using the page. Staff sign in with their token, kept in sessionStorage (gone when the
// tab closes). A kiosk gets its token in the URL fragment (#token=...): fragments never reach
// the server, so the token is not in any access log.

const KEY = "guidebot.token";

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
