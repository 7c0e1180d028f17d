// The visitor panel (/visitor/): a kiosk at the entrance or a visitor's phone. Tours and points
// in the visitor's language, a request, then live over the hub: which robot, place in line and
// wait, on its way, arrived, progress, ended; cancel. docs/visitor.md describes it.
import { html, render } from "lit-html";
import { fragmentToken } from "/lib/auth.js";
import { HubClient } from "/lib/hub.js";
import { loadTexts, preferredLanguage } from "/lib/i18n.js";
import { Api, ApiError } from "/lib/rest.js";

const options = new URLSearchParams(location.hash.slice(1));
const query = new URLSearchParams(location.search);
const token = fragmentToken();
const kiosk = (options.get("kiosk") ?? query.get("kiosk")) === "1";
const idleS = Number(options.get("idle") ?? query.get("idle") ?? 90);
const STORE = "guidebot.visitor.requests";
const FINAL = new Set(["done", "failed", "cancelled"]);

const api = new Api(() => token);
const app = document.getElementById("app");
const banner = document.getElementById("connection");

const state = {
  texts: null,
  lang: options.get("lang") ?? null,
  menu: null,
  error: "",
  /** "load" when `error` is reload()'s own (a later reload clears it), "action" when it answers
   * the visitor's tap (it stays until the next tap: a reconnect must not wipe it unread) */
  errorFrom: "",
  view: "start",
  current: null,
  /** task id -> its latest status (REST) merged with task_event payloads */
  requests: new Map(),
  labels: new Map(),
  confirming: false,
  busy: false,
  brokenPictures: new Set(),
};

const t = (key, vars) => state.texts.t(key, vars);
const about = (seconds) => t("about", { t: state.texts.duration(seconds) });

// --- data ---------------------------------------------------------------------------------------

let menuAsked = 0;
/** Reads the menu and its texts in the chosen language. Loads can overlap (a reconnect's reload and
 * a language tap): answers may come back in any order, so only the latest load's answer is kept. */
async function loadMenu() {
  const asked = ++menuAsked;
  let lang = state.lang;
  let menu = await api.get(`/api/visitor${lang ? `?lang=${encodeURIComponent(lang)}` : ""}`);
  if (!lang) {
    lang = preferredLanguage(menu.languages, menu.default_language);
    if (lang !== menu.lang) menu = await api.get(`/api/visitor?lang=${encodeURIComponent(lang)}`);
  }
  const texts = await loadTexts(menu.lang);
  if (asked !== menuAsked) return;
  if (!state.lang) state.lang = lang;
  state.menu = menu;
  state.texts = texts;
  document.documentElement.lang = menu.lang;
}

function remember() {
  const live = [...state.requests.values()].filter((r) => !FINAL.has(r.state)).map((r) => r.id);
  sessionStorage.setItem(STORE, JSON.stringify({ ids: live, labels: [...state.labels] }));
}

async function refreshRequests(ids) {
  for (const id of ids) {
    try {
      state.requests.set(id, await api.get(`/api/tasks/${encodeURIComponent(id)}`));
    } catch (err) {
      if (err instanceof ApiError && err.status === 404) state.requests.delete(id);
      else throw err;
    }
  }
}

function labelOf(status) {
  const p = status.params ?? {};
  const item = p.tour ? state.menu.tours.find((x) => x.id === p.tour) : state.menu.pois.find((x) => x.id === p.poi);
  return item?.name ?? p.tour ?? p.poi ?? status.id;
}

async function reload() {
  try {
    await loadMenu();
    // This panel's live requests (after a reload or a server restart), then the ones we follow.
    for (const status of await api.get("/api/visitor/requests")) state.requests.set(status.id, status);
    await refreshRequests([...state.requests.keys()]);
    for (const status of state.requests.values()) state.labels.set(status.id, labelOf(status));
    if (state.errorFrom !== "action") showError("", "");
  } catch (err) {
    showError(describe(err), "load");
  }
  draw();
}

function showError(text, from) {
  state.error = text;
  state.errorFrom = from;
}

let menuTimer = null;
/** Waits in the menu change with every task event: refresh them, at most every 2 s. */
function refreshMenuSoon() {
  if (menuTimer) return;
  menuTimer = setTimeout(async () => {
    menuTimer = null;
    try {
      await loadMenu();
      draw();
    } catch {
      /* the next event or reconnect tries again */
    }
  }, 2000);
}

function describe(err) {
  if (!(err instanceof ApiError)) return t("error_server", { detail: String(err) });
  if (err.status === 0) return t("error_network");
  if (err.status === 401 || err.status === 403) return t("error_token");
  if (err.status === 429) {
    const detail = typeof err.detail === "string" ? ` (${err.detail})` : "";
    return `${t("error_rate")}${detail}`;
  }
  return t("error_server", { detail: typeof err.detail === "string" ? err.detail : err.message });
}

// --- actions ------------------------------------------------------------------------------------

async function request(kind, item) {
  if (state.busy) return;
  state.busy = true;
  showError("", "");
  draw();
  const params = kind === "tour" ? { tour: item.id } : { poi: item.id };
  params.lang = state.menu.lang;
  try {
    const status = await api.post("/api/tasks", { kind, params });
    state.requests.set(status.id, status);
    state.labels.set(status.id, item.name);
    state.current = status.id;
    state.view = "request";
    state.confirming = false;
    remember();
  } catch (err) {
    showError(describe(err), "action");
  } finally {
    state.busy = false;
  }
  draw();
  focusHeading();
}

async function cancel() {
  const id = state.current;
  try {
    state.requests.set(id, await api.post(`/api/tasks/${encodeURIComponent(id)}/cancel`, { reason: "cancelled by the visitor" }));
    showError("", "");
  } catch (err) {
    showError(describe(err), "action");
  }
  state.confirming = false;
  remember();
  draw();
}

async function chooseLanguage(lang) {
  state.lang = lang;
  showError("", "");
  await reload();
}

function backToStart() {
  state.view = "start";
  state.confirming = false;
  draw();
  focusHeading();
}

function focusHeading() {
  requestAnimationFrame(() => app.querySelector("h1, h2")?.focus());
}

// --- views --------------------------------------------------------------------------------------

function picture(media, name) {
  const first = (media ?? []).find((m) => m.url && !state.brokenPictures.has(m.url));
  if (!first) return html`<div class="picture placeholder" role="img" aria-label=${t("picture_missing")}><span aria-hidden="true">🖼</span></div>`;
  const broken = () => {
    state.brokenPictures.add(first.url);
    draw();
  };
  return html`<img class="picture" src=${first.url} alt=${name} @error=${broken}>`;
}

function serviceLine(estimate) {
  if (!estimate) return "";
  if (estimate.service === "unavailable") return t("service_unavailable");
  if (estimate.service === "busy") {
    return estimate.eta_s === null ? t("service_busy_unknown") : t("service_busy", { t: state.texts.duration(estimate.eta_s) });
  }
  return t("service_available");
}

function card(kind, item) {
  const estimate = item.estimate;
  const unavailable = estimate?.service === "unavailable";
  const facts = [];
  if (kind === "tour") facts.push(t("stops", { n: item.stops.length }));
  if (estimate?.duration_s) facts.push(t("tour_length", { t: state.texts.duration(estimate.duration_s) }));
  const media = kind === "tour" ? item.stops.flatMap((s) => s.media) : item.media;
  const id = `${kind}-${item.id}`;
  return html`<article class="card" aria-labelledby=${`${id}-name`}>
    ${picture(media, item.name)}
    <div class="card-body">
      <h3 id=${`${id}-name`}>${item.name}</h3>
      ${item.description ? html`<p>${item.description}</p>` : ""}
      <p class="muted">${facts.join(" · ")}</p>
      <p class=${`wait ${estimate?.service ?? ""}`} id=${`${id}-wait`}>${serviceLine(estimate)}</p>
      <button class="big" ?disabled=${unavailable || state.busy} aria-describedby=${`${id}-name ${id}-wait`}
        @click=${() => request(kind, item)}>${t(kind === "tour" ? "request_tour" : "request_point")}</button>
    </div>
  </article>`;
}

function languagePicker() {
  const langs = state.menu.languages;
  if (langs.length < 2) return "";
  return html`<div class="languages" role="group" aria-label=${t("choose_language")}>
    ${langs.map((lang) => html`<button class="secondary" lang=${lang} aria-pressed=${String(lang === state.menu.lang)}
      @click=${() => chooseLanguage(lang)}>${names.get(lang) ?? lang}</button>`)}
  </div>`;
}

function errorBox() {
  return state.error ? html`<p class="notice error" role="alert">${state.error}</p>` : "";
}

function startView() {
  const menu = state.menu;
  const live = [...state.requests.values()].filter((r) => !FINAL.has(r.state));
  return html`<header class="visitor-top">
      <h1 tabindex="-1">${menu.site}: ${t("title")}</h1>
      ${languagePicker()}
    </header>
    <p class=${`service ${menu.service}`} role="status">${serviceLine({ service: menu.service, eta_s: menu.tours[0]?.estimate?.eta_s ?? null })}</p>
    ${errorBox()}
    ${live.length ? html`<p>${live.map((r) => html`<button class="secondary" @click=${() => { state.current = r.id; state.view = "request"; draw(); focusHeading(); }}>${t("your_request")}: ${state.labels.get(r.id) ?? r.id}</button> `)}</p>` : ""}
    <section aria-labelledby="tours-title">
      <h2 id="tours-title">${t("tours")}</h2>
      <div class="cards">${menu.tours.map((tour) => card("tour", tour))}</div>
    </section>
    <section aria-labelledby="points-title">
      <h2 id="points-title">${t("points")}</h2>
      <div class="cards">${menu.pois.map((poi) => card("poi", poi))}</div>
    </section>`;
}

function stopName(index) {
  const r = state.requests.get(state.current);
  const tour = state.menu.tours.find((x) => x.id === r?.params?.tour);
  return tour?.stops[index - 1]?.name ?? r?.progress?.poi ?? "";
}

function statusLines(r) {
  const lines = [];
  const robot = r.robot ?? "";
  const progress = r.progress;
  if (r.state === "queued") {
    if (r.service === "unavailable") lines.push(t("state_unavailable"));
    else {
      if (r.queue_position) lines.push(t("state_queued", { n: r.queue_position }));
      lines.push(r.eta_s === null ? t("service_busy_unknown") : t("state_wait", { t: state.texts.duration(r.eta_s) }));
    }
  } else if (r.state === "assigned" || r.state === "running") {
    if (!progress || progress.index === 0) {
      lines.push(t("state_assigned", { robot }));
      if (r.arrival_s !== null && r.arrival_s !== undefined) lines.push(t("state_on_its_way", { robot, t: state.texts.duration(r.arrival_s) }));
    } else {
      if (progress.index === 1 && progress.stage === "arrived") lines.push(t("state_arrived", { robot, place: stopName(1) }));
      const key = progress.stage === "explained" ? "state_explained" : "state_progress";
      lines.push(t(key, { i: progress.index, n: progress.total, place: stopName(progress.index) }));
    }
  } else if (r.state === "done") lines.push(t("state_done"));
  else if (r.state === "failed") lines.push(t("state_failed", { reason: r.reason }));
  else if (r.service === "withdrawn") lines.push(t("state_withdrawn"));
  else lines.push(t("state_cancelled"));
  return lines;
}

function requestView() {
  const r = state.requests.get(state.current);
  if (!r) return startView();
  const final = FINAL.has(r.state);
  const progress = r.progress;
  return html`<header class="visitor-top">
      <h2 tabindex="-1">${t("your_request")}: ${state.labels.get(r.id) ?? r.params.tour ?? r.params.poi}</h2>
      ${r.robot ? html`<p class="robot-name">${t("robot", { robot: r.robot })}</p>` : ""}
    </header>
    ${errorBox()}
    <div class=${`request-state ${r.state}`} role="status" aria-live="polite" aria-atomic="true">
      ${statusLines(r).map((line) => html`<p>${line}</p>`)}
    </div>
    ${progress && progress.total ? html`<label class="progress">${t("progress_label")}
      <progress max=${progress.total} value=${progress.index}>${progress.index} / ${progress.total}</progress></label>` : ""}
    <div class="actions">
      ${final ? "" : state.confirming
        ? html`<button class="big danger" @click=${cancel}>${t("cancel_confirm")}</button>
               <button class="big secondary" @click=${() => { state.confirming = false; draw(); }}>${t("keep")}</button>`
        : html`<button class="big secondary" @click=${() => { state.confirming = true; draw(); }}>${t("cancel")}</button>`}
      <button class="big" @click=${backToStart}>${final ? t("new_request") : t("back")}</button>
    </div>`;
}

const names = new Map();

function draw() {
  if (!app.dataset.drawn) {
    app.textContent = ""; // the "Loading…" placeholder, before lit-html owns the container
    app.dataset.drawn = "1";
  }
  if (!state.texts || !state.menu) {
    render(html`${errorBox()}`, app);
    return;
  }
  app.setAttribute("aria-busy", "false");
  render(state.view === "request" ? requestView() : startView(), app);
}

// --- kiosk --------------------------------------------------------------------------------------

function kioskMode() {
  document.body.classList.add("kiosk");
  // No way out by touch: no context menu, no long-press callouts; the page has no outside links.
  document.addEventListener("contextmenu", (e) => e.preventDefault());
  let timer = null;
  const reset = () => {
    clearTimeout(timer);
    timer = setTimeout(async () => {
      // The next visitor starts afresh: start screen, site's default language.
      state.view = "start";
      state.confirming = false;
      showError("", "");
      state.lang = state.menu?.default_language ?? state.lang;
      await reload();
    }, idleS * 1000);
  };
  for (const type of ["pointerdown", "keydown", "wheel", "touchstart"]) {
    document.addEventListener(type, reset, { passive: true });
  }
  reset();
}

// --- start --------------------------------------------------------------------------------------

async function start() {
  if (kiosk) kioskMode();
  const saved = JSON.parse(sessionStorage.getItem(STORE) ?? "{}");
  for (const [id, label] of saved.labels ?? []) state.labels.set(id, label);
  for (const id of saved.ids ?? []) state.requests.set(id, { id, state: "queued", params: {} });
  if (!token) {
    state.texts = await loadTexts(state.lang ?? "en");
    state.error = t("error_no_token");
    draw();
    return;
  }
  await reload();
  if (!state.menu) return;
  for (const lang of state.menu.languages) names.set(lang, (await loadTexts(lang)).name);
  draw();
  const hub = new HubClient({ token }).start();
  hub.subscribe("task_event");
  hub.on("task_event", (message) => {
    const p = message.payload;
    refreshMenuSoon();
    const known = state.requests.get(p.task_id);
    if (!known) return; // not ours (the server tells a panel's REST calls only its own)
    state.requests.set(p.task_id, { ...known, ...p, id: p.task_id });
    if (FINAL.has(p.state)) remember();
    draw();
  });
  hub.addEventListener("status", () => {
    banner.dataset.status = hub.status;
    banner.textContent = hub.status === "open" ? "" : t("connection_lost");
  });
  // After every (re)connect, e.g. a server restart, the true state comes from REST.
  hub.addEventListener("connect", () => reload());
}

start();
