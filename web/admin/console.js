// The staff console's controller: the state every view reads (`ui`), its actions (act, go,
// draw), the tabs, the banners every view shares, and the start (snapshot, then live). Each
// view draws itself (web/admin/views/*, listed in web/admin/registry.js); the map's controller
// is web/admin/livemap.js, the header's web/admin/header.js, sign-in web/lib/session.js.
import { html, render } from "lit-html";
import { mountHeader, startVenueClock } from "/admin/header.js";
import { mountMap, showBuilding } from "/admin/livemap.js";
import { RENDER, VIEWS } from "/admin/registry.js";
import { Store } from "/admin/store.js";
import { alertBar } from "/admin/views/alerts.js";
import { declareButton, emergencyBanner } from "/admin/views/emergency.js";
import { detailsView, toolbarView } from "/admin/views/map.js";
import { Modes } from "/admin/views/modes.js";
import { Monitor } from "/admin/views/monitor.js";

/**
 * The page's parts (ids in web/admin/index.html).
 * @typedef {{who: HTMLElement, connection: HTMLElement, tabs: HTMLElement, mapView: HTMLElement,
 *            view: HTMLElement, map: HTMLElement, mapToolbar: HTMLElement, details: HTMLElement,
 *            alertBar: HTMLElement, declare: HTMLElement, emergencyBanner: HTMLElement,
 *            pageError: HTMLElement, statusLine: HTMLElement}} ConsoleParts
 */

/**
 * The signed-in person or token, as GET /api/me answers.
 * @typedef {{name: string, role: string}} Me
 */

/**
 * Start the console for `me`: open the live connection, load the snapshot, draw the view the
 * tab last showed. When `signal` aborts (the sign-in ended) it stops: no timer, listener or
 * late answer of it draws on the page again, and its map leaves the page's element.
 * @param {import("/lib/session.js").StaffSession<Me>} session
 * @param {Me} me
 * @param {AbortSignal} signal
 * @param {ConsoleParts} parts
 * @returns {Promise<void>}
 */
export async function startConsole(session, me, signal, parts) {
  const { api } = session;
  const hub = session.connect(parts.connection);
  // The status line may cut the banner short: its whole text in its tooltip.
  hub.addEventListener("status", () => { parts.connection.title = parts.connection.textContent ?? ""; });
  hub.addEventListener("status", () => {
    if (hub.status === "refused") session.signInAgain(`The server closed the live connection: ${hub.reason}. Sign in again.`);
  });
  const store = new Store(api, hub);
  const remembered = sessionStorage.getItem("guidebot.view");
  const ui = {
    me,
    store,
    api,
    hub,
    admin: me.role === "admin",
    operate: me.role !== "viewer", // a viewer sees every view and no button that changes anything
    view: (session.account || remembered !== "passkeys") ? remembered ?? "map" : "map",
    selected: null,
    notice: null,
    sound: false,
    draw: () => draw(),
  };

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

  mountHeader(ui, session, parts.who, signal);
  parts.tabs.hidden = false;
  parts.statusLine.hidden = false;

  const map = mountMap(ui, parts.map);
  ui.map = map;
  signal.addEventListener("abort", () => {
    store.stop();
    ui.monitor.close();
    map.remove();
  }, { once: true });
  installProbe(map, () => draw());
  let alarmShown = false;
  ui.monitor = new Monitor(ui);
  ui.modes = new Modes(ui);
  store.addEventListener("alert", () => {
    if (ui.sound) beep();
  });

  function draw() {
    if (!store.site || signal.aborted) return;
    const open = store.openAlerts();
    document.title = open.length ? `(${open.length}) GuideBot console` : "GuideBot console";
    render(alertBar(ui, open), parts.alertBar);
    const alarm = store.emergency && store.emergency.state !== "normal";
    if (!alarm) ui.resumeRefusal = null;
    if (Boolean(alarm) !== alarmShown) {
      alarmShown = Boolean(alarm);
      map.restyleRobots(); // the evacuation rings come and go with the alarm
    }
    parts.emergencyBanner.hidden = !alarm;
    render(emergencyBanner(ui), parts.emergencyBanner);
    render(declareButton(ui), parts.declare);
    const refresh = store.error ? `The console could not refresh: ${store.error} It tries again when the server is back.` : "";
    render(refresh ? html`<span role="alert" title=${refresh}>${refresh}</span>` : "", parts.pageError);
    render(
      VIEWS.filter(([, , only]) => !only || me.role === only).map(
        ([id, label]) => html`<button type="button" class="secondary" aria-current=${ui.view === id ? "page" : "false"}
            @click=${() => ui.go(id)}>${label}${id === "alerts" && open.length ? html`<span class="count" aria-label=${`${open.length} open`}>${open.length}</span>` : ""}</button>`,
      ),
      parts.tabs,
    );
    parts.mapView.hidden = ui.view !== "map";
    parts.view.hidden = ui.view === "map";
    if (ui.view === "map") {
      render(toolbarView(ui), parts.mapToolbar);
      render(detailsView(ui), parts.details);
    } else {
      const notice = ui.notice
        ? html`<p class=${`notice ${ui.notice.ok ? "ok" : "error"}`} role=${ui.notice.ok ? "status" : "alert"}>${ui.notice.text}</p>`
        : "";
      render(html`<div class="view-notice">${notice}</div>${RENDER[ui.view](ui)}`, parts.view);
    }
  }
  store.addEventListener("change", draw);
  try {
    await store.start();
    if (signal.aborted) return;
    startVenueClock(parts.who, signal);
    ui.go(ui.view);
    await map.setSite(store.site);
    if (signal.aborted) return;
    await store.reload();
    if (signal.aborted) return;
    await ui.modes.start();
  } catch (err) {
    if (!signal.aborted) render(html`<p class="notice error" role="alert">${err.message}</p>`, parts.details);
    return;
  }
  if (!signal.aborted) showBuilding(store, map);
}

/**
 * The console's measurement probe, for the benchmark (bench/console.py) and the browser tests:
 * numbers measured in the page (docs/web.md: measure with performance.now(), report through
 * page.evaluate) and a redraw as a live update would cause one. Not the console's state:
 * tests act and look through the page itself.
 * @param {import("/lib/map.js").FloorMap} map
 * @param {() => void} redraw
 */
function installProbe(map, redraw) {
  /** @type {any} */ (window).guidebotProbe = Object.freeze({
    /** Latencies (ms) from a robot_state's timestamp to its marker drawn, since the last call. */
    takeLatencies: () => map.takeLatencies(),
    /** Redraw the console now, as a live update does (a drag must survive it). */
    redraw,
  });
}

/** A short tone for a new alert (the banner and the title say it too). */
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
