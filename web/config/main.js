// The site editor (/config, installers and admins): sign in (web/lib/session.js), then the
// editor (web/config/editor.js): edit the draft on the plan, publish it live, history.
import { startEditor } from "/config/editor.js";
import { StaffSession } from "/lib/session.js";

const EDITORS = new Set(["admin", "installer"]);
const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));

/**
 * The signed-in person or token if it may edit the site, else an Error saying why not.
 * @param {import("/lib/rest.js").Api} api
 * @returns {Promise<import("/config/editor.js").Me | Error>}
 */
async function editor(api) {
  const me = await api.get("/api/me").catch((err) => err);
  if (me instanceof Error) return me;
  if (!EDITORS.has(me.role)) {
    return new Error(`You are signed in as ${me.name} (role ${me.role}); the site editor is for installers and administrators.`);
  }
  return me;
}

/** @type {StaffSession<import("/config/editor.js").Me>} */
const session = new StaffSession({
  section: $("signin"),
  intro: "The site editor is for installers and administrators.",
  tokenLabel: "Admin token",
  missing: "Enter your account name and password, or an admin token.",
  check: editor,
  hide: () => { $("editor").hidden = true; },
  start: (me) => startEditor(session, me, {
    editor: $("editor"),
    connection: $("connection"),
    bar: $("bar"),
    notices: $("notices"),
    lists: $("lists"),
    mapToolbar: $("map-toolbar"),
    map: $("map"),
    details: $("details"),
    translations: $("translations"),
    views: $("views"),
    columns: $("columns"),
  }),
});
session.boot();
