// The staff console (/admin): sign-in, then the live map and the fleet views.
import { html, render } from "lit-html";
import { currentToken, forgetToken, saveToken } from "/lib/auth.js";
import { connectionBanner } from "/lib/dom.js";
import { HubClient } from "/lib/hub.js";
import { FloorMap } from "/lib/map.js";
import { Api, ApiError } from "/lib/rest.js";
import { Store } from "/admin/store.js";
import { detailsView, toolbarView } from "/admin/views/map.js";

const STAFF_ROLES = new Set(["admin", "operator"]);
const $ = (id) => document.getElementById(id);

let token = currentToken();
const api = new Api(() => token);

function showSignIn(message = "") {
  $("tabs").hidden = true;
  $("map-view").hidden = true;
  $("view").hidden = true;
  const section = $("signin");
  section.hidden = false;
  const submit = async (event) => {
    event.preventDefault();
    const value = new FormData(event.target).get("token").trim();
    if (!value) return showSignIn("Enter your staff token.");
    token = value;
    const me = await whoAmI();
    if (me instanceof Error) {
      token = null;
      return showSignIn(me.message);
    }
    saveToken(value);
    start();
  };
  render(
    html`<h2>Sign in</h2>
      <p>Staff of the front desk and administrators sign in with their token.</p>
      <form @submit=${submit}>
        <label>Staff token <input name="token" type="password" autocomplete="current-password" required></label>
        <button type="submit">Sign in</button>
      </form>
      ${message ? html`<p class="notice error" role="alert">${message}</p>` : ""}`,
    section,
  );
  section.querySelector("input").focus();
}

/** The signed-in user (or an Error that says why not). */
async function whoAmI() {
  try {
    const me = await api.get("/api/me");
    if (!STAFF_ROLES.has(me.role)) {
      return new Error(`This token belongs to ${me.name} (role ${me.role}); the console is for operators and admins.`);
    }
    return me;
  } catch (err) {
    return err instanceof ApiError ? err : new Error(String(err));
  }
}

async function start() {
  if (!token) return showSignIn();
  const me = await whoAmI();
  if (me instanceof Error) {
    forgetToken();
    token = null;
    return showSignIn(me.message);
  }
  const hub = new HubClient({ token }).start();
  connectionBanner(hub, $("connection"));
  hub.addEventListener("status", () => {
    if (hub.status === "refused") {
      forgetToken();
      showSignIn(`The server closed the live connection: ${hub.reason}. Sign in again.`);
    }
  });
  api.addEventListener("denied", (event) => {
    if (event.detail.status === 401) {
      hub.stop();
      forgetToken();
      showSignIn(event.detail.message);
    }
  });
  const store = new Store(api, hub);
  const ui = { me, store, api, hub, selected: null, notice: null };
  window.guidebotConsole = ui; // for the browser tests and the benchmark

  render(
    html`<span>${me.name} <span class="badge">${me.role}</span></span>
      <button type="button" @click=${() => { hub.stop(); forgetToken(); location.reload(); }}>Sign out</button>`,
    $("who"),
  );
  $("signin").hidden = true;
  $("map-view").hidden = false;

  const map = new FloorMap($("map"), (url) => api.get(url));
  ui.map = map;
  store.addEventListener("robot_state", (e) => map.updateRobot(e.detail));
  store.addEventListener("robot_offline", (e) => map.robotOffline(e.detail));
  store.addEventListener("lock", (e) => map.setAreaState(e.detail));
  map.addEventListener("select", (e) => {
    ui.selected = e.detail;
    if (e.detail.kind === "robot") map.selectRobot(e.detail.id);
    draw();
  });
  map.addEventListener("floor", () => draw());

  function draw() {
    if (!store.site) return;
    render(toolbarView(ui), $("map-toolbar"));
    render(detailsView(ui), $("details"));
  }
  store.addEventListener("change", draw);
  try {
    await store.start();
  } catch (err) {
    render(html`<p class="notice error" role="alert">${err.message}</p>`, $("details"));
    return;
  }
  await map.setSite(store.site);
  for (const view of store.locks.values()) map.setAreaState(view);
  draw();
}

start();
