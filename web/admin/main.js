// The staff console (/admin/): sign in (web/lib/session.js), then the console
// (web/admin/console.js): the live map and the fleet views.
import { render } from "lit-html";
import { startConsole } from "/admin/console.js";
import { ApiError } from "/lib/rest.js";
import { StaffSession } from "/lib/session.js";

const STAFF_ROLES = new Set(["admin", "operator", "viewer"]); // viewers watch: the rule `watch`
const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));

/**
 * The signed-in user, or an Error that says why the console does not serve them.
 * @param {import("/lib/rest.js").Api} api
 * @returns {Promise<import("/admin/console.js").Me | Error>}
 */
async function whoAmI(api) {
  try {
    const me = await api.get("/api/me");
    if (!STAFF_ROLES.has(me.role)) {
      return new Error(`You are signed in as ${me.name} (role ${me.role}); the console is for operators, viewers and admins.`);
    }
    return me;
  } catch (err) {
    return err instanceof ApiError ? err : new Error(String(err));
  }
}

/** The console signed in now, stopped when the sign-in form shows again (a 401, a refused live
 * connection): its timers, map and listeners go with it, so the next sign-in starts one
 * console, not a second one beside a stale first (signing in again found the map taken: "Map
 * container is already initialized", and the console never showed). */
let running = new AbortController();

/** @type {StaffSession<import("/admin/console.js").Me>} */
const session = new StaffSession({
  section: $("signin"),
  intro: "Staff sign in with their account; a shared screen or the demo with a staff token.",
  missing: "Enter your account name and password, or a staff token.",
  check: whoAmI,
  hide() {
    running.abort();
    render("", $("who")); // no name, role nor "Sign out" of a sign-in that ended
    render("", $("page-error"));
    $("tabs").hidden = true;
    $("status-line").hidden = true;
    $("map-view").hidden = true;
    $("view").hidden = true;
    render("", $("alert-bar"));
    render("", $("declare"));
    $("emergency-banner").hidden = true;
  },
  start: (me) => startConsole(session, me, (running = new AbortController()).signal, {
    who: $("who"),
    connection: $("connection"),
    tabs: $("tabs"),
    mapView: $("map-view"),
    view: $("view"),
    map: $("map"),
    mapToolbar: $("map-toolbar"),
    details: $("details"),
    alertBar: $("alert-bar"),
    declare: $("declare"),
    emergencyBanner: $("emergency-banner"),
    pageError: $("page-error"),
    statusLine: $("status-line"),
  }),
});
session.boot();
