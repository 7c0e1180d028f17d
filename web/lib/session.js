// Who a staff page serves, the same way on the console, the site editor and the net editor: a
// token (typed here, or a kiosk's #token=...) or an account's session cookie; the sign-in form
// until someone the page serves signs in; a 401 or a refused live connection sends the page
// back to it; signing out. The page's REST client, file uploads and live connection go under
// the same sign-in. One module, so the three pages cannot drift apart (docs/console.md).
import { currentSession, currentToken, forgetToken, sessionHeaders, signOut, signOutEverywhere } from "/lib/auth.js";
import { connectionBanner } from "/lib/dom.js";
import { HubClient } from "/lib/hub.js";
import { Api, ApiError } from "/lib/rest.js";
import { signInFlow } from "/lib/signin.js";

/**
 * What a page tells its session.
 * @template T
 * @typedef {object} PageSignIn
 * @property {HTMLElement} section  where the sign-in form goes (shown only while signed out)
 * @property {string} intro  the form's first sentence: whom the page is for
 * @property {string} missing  what to say when the name or the password is left out
 * @property {string} [tokenLabel]  the token field's label (default "Staff token")
 * @property {(api: Api) => Promise<T | Error>} check  whom the page serves (the signed-in
 *   person or token, with what the page needs to start), or an Error saying why not
 * @property {(known: T) => unknown} start  the page, once someone it serves signed in
 * @property {() => void} [hide]  hide the page while the form shows
 */

/**
 * The account's session (the HttpOnly cookie's, as GET /api/session answers it).
 * @typedef {{signed_in: boolean, name: string, display_name?: string, role: string,
 *            csrf: string, expires_at?: number, sso?: string | null}} AccountSession
 */

/**
 * A staff page's sign-in, REST client and live connection.
 * @template T
 */
export class StaffSession {
  /** @param {PageSignIn<T>} page */
  constructor(page) {
    this.page = page;
    /** @type {string | null} the token this page uses; null: the account's session cookie */
    this.token = currentToken();
    /** @type {AccountSession | null} the account's session, when signed in with an account */
    this.account = null;
    /** The page's REST client: the token, or the cookie with its CSRF token. */
    this.api = new Api(() => this.token, () => (this.token ? {} : sessionHeaders()));
    /** @type {HubClient | null} the live connection, once the page opened it */
    this.hub = null;
    /** Whether the page is showing (signed in); a 401 then sends it back to the form. */
    this.live = false;
    this.api.addEventListener("denied", (event) => {
      const error = /** @type {CustomEvent<ApiError>} */ (event).detail;
      if (this.live && error.status === 401) this.signInAgain(error.message);
    });
  }

  /** Start the page: with the token or the session cookie it already has, else the form. */
  async boot() {
    if (!this.token) this.account = await currentSession();
    if (!this.token && !this.account) return this.showSignIn();
    const known = await this.page.check(this.api);
    if (known instanceof Error) {
      forgetToken();
      this.token = null;
      this.account = null; // another page (the site editor) may still use it: sign in as someone else here
      return this.showSignIn(known.message);
    }
    return this.#begin(known);
  }

  /**
   * Show the sign-in form (the page hidden), with `message` said first when given.
   * @param {string} [message]
   */
  showSignIn(message = "") {
    this.live = false;
    this.page.hide?.();
    const { section } = this.page;
    section.hidden = false;
    signInFlow({
      section,
      intro: this.page.intro,
      tokenLabel: this.page.tokenLabel,
      message,
      missing: this.page.missing,
      useToken: (value) => { this.token = value; },
      check: () => this.page.check(this.api),
      done: async (known) => {
        this.account = this.token ? null : await currentSession();
        return this.#begin(known);
      },
      again: (text) => this.showSignIn(text),
    });
  }

  /**
   * The sign-in ended (a 401, a refused live connection): stop the live connection, forget
   * this tab's token and show the form with why.
   * @param {string} message
   */
  signInAgain(message) {
    if (this.hub && this.hub.status !== "refused") this.hub.stop(); // a refused one says why
    this.hub = null;
    forgetToken();
    this.showSignIn(message);
  }

  /**
   * Sign out: this browser's session, or every session of the account; the page starts again.
   * @param {boolean} [everywhere]
   */
  async signOut(everywhere = false) {
    this.hub?.stop();
    forgetToken();
    if (this.account) await (everywhere ? signOutEverywhere() : signOut()).catch(() => {});
    location.reload();
  }

  /**
   * Open the live connection under this sign-in, its state shown in `banner`.
   * @param {HTMLElement} banner  a role=status element
   * @returns {HubClient}
   */
  connect(banner) {
    const hub = new HubClient({ token: this.token }).start();
    connectionBanner(hub, banner);
    this.hub = hub;
    return hub;
  }

  /**
   * Send a file (YAML, PNML, an image, a translation file): the REST client sends JSON only.
   * Resolves to the answer's JSON; rejects with an ApiError whose message the page can show.
   * @param {string} method
   * @param {string} path
   * @param {BodyInit} body
   * @param {string} type  the file's Content-Type
   * @returns {Promise<any>}
   */
  async sendFile(method, path, body, type) {
    let response;
    try {
      const auth = this.token ? { Authorization: `Bearer ${this.token}` } : sessionHeaders();
      response = await fetch(path, { method, body, headers: { ...auth, "Content-Type": type, Accept: "application/json" } });
    } catch {
      throw new ApiError(0, "The server cannot be reached: check the network.");
    }
    const data = await response.json().catch(() => ({}));
    if (!response.ok) {
      const detail = data.detail ?? null;
      throw new ApiError(response.status, fileRefusal(detail, response.status), detail);
    }
    return data;
  }

  /**
   * @param {T} known
   */
  #begin(known) {
    this.live = true;
    this.page.section.hidden = true;
    return this.page.start(known);
  }
}

/**
 * Why a file was refused, from the answer's detail: its text, the problems' messages, or the
 * status.
 * @param {unknown} detail
 * @param {number} status
 * @returns {string}
 */
function fileRefusal(detail, status) {
  if (typeof detail === "string") return detail;
  if (Array.isArray(detail)) return detail.map((d) => (typeof d === "string" ? d : d?.msg)).join("; ");
  const msg = /** @type {{msg?: unknown} | null} */ (detail)?.msg;
  return typeof msg === "string" ? msg : `the server answered ${status}`;
}
