// The staff console (/admin/): sign-in, then the live map and the fleet views.
import { html, render } from "lit-html";
import {
  addPasskey, currentSession, currentToken, forgetToken, passkeysAvailable, sessionHeaders, signOut, signOutEverywhere,
} from "/lib/auth.js";
import { connectionBanner } from "/lib/dom.js";
import { HubClient } from "/lib/hub.js";
import { FloorMap } from "/lib/map.js";
import { Api, ApiError } from "/lib/rest.js";
import { signInFlow } from "/lib/signin.js";
import { accountsView, passkeysView } from "/admin/views/accounts.js";
import { robotDoing } from "/admin/names.js";
import { Store } from "/admin/store.js";
import { alertBar, alertsView } from "/admin/views/alerts.js";
import { bookingsView } from "/admin/views/bookings.js";
import { buildingView } from "/admin/views/building.js";
import { declareButton, emergencyBanner } from "/admin/views/emergency.js";
import { eventsView } from "/admin/views/events.js";
import { fleetView } from "/admin/views/fleet.js";
import { locksView } from "/admin/views/locks.js";
import { detailsView, toolbarView } from "/admin/views/map.js";
import { Modes, modesView } from "/admin/views/modes.js";
import { Monitor, monitorView } from "/admin/views/monitor.js";
import { notificationsView } from "/admin/views/notifications.js";
import { reportsView } from "/admin/views/reports.js";
import { robotsView } from "/admin/views/robots.js";
import { tasksView } from "/admin/views/tasks.js";

const STAFF_ROLES = new Set(["admin", "operator", "viewer"]); // viewers watch: the rule `watch`
const VIEWS = [
  ["map", "Map"],
  ["robots", "Robots"],
  ["tasks", "Tasks"],
  ["fleet", "Fleet"],
  ["locks", "Locks"],
  ["building", "Building"],
  ["modes", "Modes"],
  ["bookings", "Bookings"],
  ["monitor", "RoboGraph monitor"],
  ["alerts", "Alerts"],
  ["events", "Event log"],
  ["reports", "Reports"],
  ["notifications", "Notifications"],
  ["accounts", "Accounts", "admin"],
];
const RENDER = {
  robots: robotsView,
  tasks: tasksView,
  fleet: fleetView,
  locks: locksView,
  building: buildingView,
  modes: modesView,
  bookings: bookingsView,
  monitor: monitorView,
  alerts: alertsView,
  events: eventsView,
  reports: reportsView,
  accounts: accountsView,
  notifications: notificationsView,
  passkeys: passkeysView, // from the header's "Your passkeys", not a tab
};
const $ = (id) => document.getElementById(id);

let token = currentToken();
let session = null; // a person's session (the cookie's), when signed in with an account
const api = new Api(() => token, () => (token ? {} : sessionHeaders()));

function showSignIn(message = "") {
  $("tabs").hidden = true;
  $("map-view").hidden = true;
  $("view").hidden = true;
  render("", $("alert-bar"));
  render("", $("declare"));
  $("emergency-banner").hidden = true;
  const section = $("signin");
  section.hidden = false;
  signInFlow({
    section,
    intro: "Staff sign in with their account; a shared screen or the demo with a staff token.",
    message,
    missing: "Enter your account name and password, or a staff token.",
    useToken: (value) => { token = value; },
    check: whoAmI,
    done: start,
    again: showSignIn,
  });
}

/** The signed-in user (or an Error that says why not). */
async function whoAmI() {
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

function beep() {
  try {
    const audio = new AudioContext();
    const tone = audio.createOscillator();
    tone.frequency.value = 880;
    tone.connect(audio.destination);
    tone.start();
    tone.stop(audio.currentTime + 0.25);
  } catch {
    // no audio device: the banner and the title still say it
  }
}

async function start() {
  if (!token) session = await currentSession();
  if (!token && !session) return showSignIn();
  const me = await whoAmI();
  if (me instanceof Error) {
    forgetToken();
    token = null;
    session = null; // another page (the site editor) may still use it: sign in as someone else here
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
  const ui = {
    me,
    store,
    api,
    hub,
    admin: me.role === "admin",
    operate: me.role !== "viewer", // a viewer sees every view and no button that changes anything
    view: (session || sessionStorage.getItem("guidebot.view") !== "passkeys") ? sessionStorage.getItem("guidebot.view") ?? "map" : "map",
    selected: null,
    notice: null,
    sound: false,
    draw: () => draw(),
  };
  window.guidebotConsole = ui; // for the browser tests and the benchmark

  /** Run a REST action; its outcome (or the reason it failed) is shown on the page. */
  ui.act = async (label, fn) => {
    try {
      await fn();
      ui.notice = { ok: true, text: `${label}: done.` };
    } catch (err) {
      ui.notice = { ok: false, text: `${label}: ${err.message}` };
    }
    draw();
  };
  ui.go = (view) => {
    ui.view = view;
    ui.notice = null;
    sessionStorage.setItem("guidebot.view", view);
    if (view === "monitor") ui.monitor.open();
    else ui.monitor.close();
    draw();
    if (view === "map") ui.map.shown();
  };

  const leave = async (everywhere) => {
    hub.stop();
    forgetToken();
    if (session) await (everywhere ? signOutEverywhere() : signOut()).catch(() => {});
    location.reload();
  };
  render(
    html`<span id="server-status" role="status"></span>
      <span>${session?.display_name || me.name} <span class="badge">${me.role}</span></span>
      ${ui.operate ? "" : html`<span id="read-only">Read only: a viewer watches, changes nothing.</span>`}
      <button type="button" @click=${() => leave(false)}>Sign out</button>
      ${session ? html`<button type="button" class="secondary" @click=${() => leave(true)}>Sign out everywhere</button>` : ""}
      ${session && passkeysAvailable()
        ? html`<button type="button" class="secondary" @click=${() => ui.act("Add a passkey", async () => {
          await addPasskey(navigator.platform || "");
          ui.passkeys = undefined; // "Your passkeys" reads them again
        })}>Add a passkey</button>`
        : ""}
      ${session ? html`<button type="button" class="secondary" @click=${() => ui.go("passkeys")}>Your passkeys</button>` : ""}`,
    $("who"),
  );
  const showServer = () => serverStatus(api).then((view) => render(view, $("server-status")));
  showServer();
  hub.addEventListener("connect", showServer);
  setInterval(showServer, SERVER_REFRESH_MS);
  $("signin").hidden = true;
  $("tabs").hidden = false;

  const map = new FloorMap($("map"), (url) => api.get(url));
  ui.map = map;
  map.describeRobot = (s) => robotDoing(store, s);
  map.evacuationOf = (name) => store.evacuation(name)?.state ?? null;
  store.addEventListener("evacuation", () => map.restyleRobots());
  let alarmShown = false;
  ui.monitor = new Monitor(ui);
  ui.modes = new Modes(ui);
  let pathKey = "";
  store.addEventListener("robot_state", (e) => {
    map.updateRobot(e.detail);
    const s = e.detail.payload;
    if (ui.selected?.kind === "robot" && ui.selected.id === s.robot) {
      const key = `${s.node}|${s.task_id}|${s.poi}`;
      if (key !== pathKey) {
        pathKey = key;
        showPath(s.robot);
      }
    }
  });
  store.addEventListener("robot_offline", (e) => map.robotOffline(e.detail));
  store.addEventListener("lock", (e) => map.setAreaState(e.detail));
  store.addEventListener("door", (e) => map.setDoor(e.detail, store.doors.get(e.detail)));
  store.addEventListener("lift", (e) => {
    const lift = store.lifts.get(e.detail);
    map.setElevator(e.detail, lift.floor, lift.door_open);
  });
  store.addEventListener("alert", () => {
    if (ui.sound) beep();
  });
  map.addEventListener("select", async (e) => {
    ui.selected = e.detail;
    if (e.detail.kind === "robot") {
      map.selectRobot(e.detail.id);
      await showPath(e.detail.id);
    } else {
      map.selectRobot(null);
      map.setPath([]);
    }
    draw();
  });
  map.addEventListener("floor", () => draw());

  /** The selected robot's planned path: from where it is to its task's goal. */
  async function showPath(name) {
    const robot = store.robots.get(name);
    const task = robot?.state?.task_id ? store.tasks.get(robot.state.task_id) : null;
    const goal = task ? goalNode(store.site, task, robot.state.poi, robot.state.node) : null;
    if (!goal || !robot.state.node) return map.setPath([]);
    try {
      const path = await api.get(`/api/paths?from_node=${encodeURIComponent(robot.state.node)}&to_node=${encodeURIComponent(goal)}`);
      map.setPath(path.nodes);
    } catch {
      map.setPath([]);
    }
  }

  function draw() {
    if (!store.site) return;
    const open = store.openAlerts();
    document.title = open.length ? `(${open.length}) GuideBot console` : "GuideBot console";
    render(alertBar(ui, open), $("alert-bar"));
    const alarm = ui.store.emergency && ui.store.emergency.state !== "normal";
    if (!alarm) ui.resumeRefusal = null;
    if (Boolean(alarm) !== alarmShown) {
      alarmShown = Boolean(alarm);
      map.restyleRobots(); // the evacuation rings come and go with the alarm
    }
    $("emergency-banner").hidden = !alarm;
    render(emergencyBanner(ui), $("emergency-banner"));
    render(declareButton(ui), $("declare"));
    render(
      store.error ? html`<p class="notice error" role="alert">The console could not refresh: ${store.error} It tries again when the server is back.</p>` : "",
      $("page-error"),
    );
    render(
      VIEWS.filter(([, , only]) => !only || me.role === only).map(
        ([id, label]) => html`<button type="button" class="secondary" aria-current=${ui.view === id ? "page" : "false"}
            @click=${() => ui.go(id)}>${label}${id === "alerts" && open.length ? html`<span class="count" aria-label=${`${open.length} open`}>${open.length}</span>` : ""}</button>`,
      ),
      $("tabs"),
    );
    $("map-view").hidden = ui.view !== "map";
    $("view").hidden = ui.view === "map";
    if (ui.view === "map") {
      render(toolbarView(ui), $("map-toolbar"));
      render(detailsView(ui), $("details"));
    } else {
      const notice = ui.notice
        ? html`<p class=${`notice ${ui.notice.ok ? "ok" : "error"}`} role=${ui.notice.ok ? "status" : "alert"}>${ui.notice.text}</p>`
        : "";
      render(html`${notice}${RENDER[ui.view](ui)}`, $("view"));
    }
  }
  store.addEventListener("change", draw);
  try {
    await store.start();
    ui.go(ui.view);
    await map.setSite(store.site);
    await store.reload();
    await ui.modes.start();
  } catch (err) {
    render(html`<p class="notice error" role="alert">${err.message}</p>`, $("details"));
    return;
  }
  for (const view of store.locks.values()) map.setAreaState(view);
  for (const [id, open] of store.doors) map.setDoor(id, open);
  for (const [id, lift] of store.lifts) if (lift.floor) map.setElevator(id, lift.floor, lift.door_open);
}

const SERVER_REFRESH_MS = 15000;

/** The header's server line from /api/health: with several server processes, which one
 * serves this page and which one leads (decides tasks, areas and the building). */
async function serverStatus(api) {
  const health = await api.get("/api/health").catch(() => null);
  if (!health) return html`<span class="badge bad">server unreachable</span>`;
  const c = health.cluster;
  const state = html`<span class=${`badge ${health.status === "ok" ? "ok" : "warn"}`}>${health.status}</span>`;
  if (!c) return html`Server ${state}`;
  const leader = c.leader ? `leader ${c.leader} (epoch ${c.epoch})` : "no leader yet";
  return html`Process ${c.process} <span class="badge">${c.leading ? "leads" : "follows"}</span> · ${leader} ${state}`;
}

/** The node a task is heading for (a tour: the point after the one it showed last, or the
 * one after that when the robot already stands there). */
export function goalNode(site, task, poi, here = null) {
  const p = task.params ?? {};
  if (p.node) return p.node;
  const poiNode = (id) => site.pois.find((x) => x.id === id)?.node;
  if (p.poi) return poiNode(p.poi);
  if (p.station) return site.charging_stations.find((s) => s.id === p.station)?.node;
  if (p.tour) {
    const tour = site.tours.find((t) => t.id === p.tour);
    if (!tour) return null;
    let next = Math.min((poi ? tour.points.indexOf(poi) : -1) + 1, tour.points.length - 1);
    if (poiNode(tour.points[next]) === here) next = Math.min(next + 1, tour.points.length - 1);
    return poiNode(tour.points[next]);
  }
  return null;
}

start();
