// The visitor panel (/visitor/): a kiosk at the entrance or a visitor's phone. Tours and points
// in the visitor's language, a request, then live over the hub: which robot, place in line and
// wait, on its way, arrived, progress, ended; cancel. During a fire alarm, the evacuation screen;
// after it, the offer to go on with a request the alarm cut off. docs/visitor.md describes it.
import { html, nothing, render } from "lit-html";
import { fragmentToken } from "/lib/auth.js";
import { HubClient } from "/lib/hub.js";
import { loadTexts, preferredLanguage } from "/lib/i18n.js";
import { Api, ApiError } from "/lib/rest.js";
import { nextTourLines } from "/lib/nexttours.js";
import { skipReason, skippedLines } from "/lib/skipped.js";

const options = new URLSearchParams(location.hash.slice(1));
const query = new URLSearchParams(location.search);
const token = fragmentToken();
const kiosk = (options.get("kiosk") ?? query.get("kiosk")) === "1";
const idleS = Number(options.get("idle") ?? query.get("idle") ?? 90);
const STORE = "guidebot.visitor.requests";
const DEVICE = "guidebot.visitor.device";
const FINAL = new Set(["done", "failed", "cancelled"]);
/** task_event of tasks this page has not been told of yet, with their server time: its own
 * request's answer may come after the hub's first news of it (a point visit assigned and
 * started at once, or even back in line already). Bounded. */
const early = new Map();
const EARLY_MAX = 64;
/** The kinds the panel asks for, by card (docs/visitor.md). */
const KIND = { tour: "tour", poi: "go_to_poi" };
/** The reason the server gives a task it cut off for a fire alarm (docs/emergency.md). */
const CUT_OFF = "fire alarm";

/** A random id, 22 URL-safe characters: this device's identity under the shared panel token. */
function newDevice() {
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  return btoa(String.fromCharCode(...bytes)).replace(/\+/g, "-").replace(/\//g, "_").replace(/=+$/, "");
}

/** This device's id (docs/visitor.md, "Devices"): a phone keeps it (localStorage), so it finds
 * its requests again after a reload; a kiosk has a new one for each visitor (sessionStorage,
 * replaced when the kiosk goes back to the start screen). */
function deviceId(fresh = false) {
  const store = kiosk ? sessionStorage : localStorage;
  let id = fresh ? null : store.getItem(DEVICE);
  if (!id) {
    id = newDevice();
    store.setItem(DEVICE, id);
  }
  return id;
}
let device = deviceId();

const api = new Api(() => token, () => ({ "X-Guidebot-Device": device }));
const app = document.getElementById("app");
const banner = document.getElementById("connection");

const state = {
  texts: null,
  lang: options.get("lang") ?? null,
  /** the visitor asked for a slower tour (docs/accessibility.md): the menu's lengths and the
   * requests are at that pace */
  slow: false,
  /** the visitor asked for step-free tours: no steps on the way, stops only steps lead to skipped */
  stepFree: false,
  menu: null,
  /** when the menu (and its waits) was read: its waits count down from then */
  menuAt: 0,
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
  /** the server's emergency state (GET /api/emergency, then emergency_changed) */
  emergency: null,
  /** today's coming public booked tours (GET /api/bookings/next, then next_tours) */
  nextTours: [],
  /** this device's requests a fire alarm cut off, not yet answered after it (the offer) */
  cutOff: new Set(),
  /** robot -> what it is saying now {text, lang, started_at (Unix s), shown_at (Unix ms)} */
  speaking: new Map(),
};

/** The last captions shown, as on the touch screen: how late each came (tests, the console). */
const captionsShown = [];
window.captionsShown = captionsShown;

const t = (key, vars) => state.texts.t(key, vars);
const about = (seconds) => t("about", { t: state.texts.duration(seconds) });

// --- data ---------------------------------------------------------------------------------------

let menuAsked = 0;
/** Reads the menu and its texts in the chosen language. Loads can overlap (a reconnect's reload and
 * a language tap): answers may come back in any order, so only the latest load's answer is kept. */
async function loadMenu() {
  const asked = ++menuAsked;
  let lang = state.lang;
  const pace = state.slow ? "pace=slow" : "";
  const stepFree = state.stepFree ? "step_free=true" : ""; // the lengths of step-free tours
  const query = (l) => `/api/visitor?${[l ? `lang=${encodeURIComponent(l)}` : "", pace, stepFree].filter(Boolean).join("&")}`;
  let menu = await api.get(query(lang));
  if (!lang) {
    lang = preferredLanguage(menu.languages, menu.default_language);
    if (lang !== menu.lang) menu = await api.get(query(lang));
  }
  const texts = await loadTexts(menu.lang);
  if (asked !== menuAsked) return;
  if (!state.lang) state.lang = lang;
  state.menu = menu;
  state.menuAt = performance.now();
  state.texts = texts;
  document.documentElement.lang = menu.lang;
}

function remember() {
  const live = [...state.requests.values()].filter((r) => !FINAL.has(r.state)).map((r) => r.id);
  for (const id of state.cutOff) if (!live.includes(id)) state.cutOff.delete(id);
  sessionStorage.setItem(STORE, JSON.stringify({ ids: live, labels: [...state.labels], cutOff: [...state.cutOff] }));
}

/** An alarm holds the service (the evacuation screen shows). */
const alarm = () => Boolean(state.emergency && state.emergency.state !== "normal");

/** The server's emergency state; the requests it cut off are this device's to offer again. */
async function loadEmergency() {
  const emergency = await api.get("/api/emergency");
  state.emergency = emergency;
  markCutOff(emergency.cut_off_tasks ?? []);
}

function markCutOff(ids) {
  let more = false;
  for (const id of ids) {
    const r = state.requests.get(id);
    if (r && !FINAL.has(r.state) && !state.cutOff.has(id)) {
      state.cutOff.add(id);
      more = true;
    }
  }
  if (more) remember();
}

/** A task's status as told by the server now: its waits count down from `toldAt`. `at` is
 * the server time (Unix s) of that news: a task_event's message time, a REST status's last
 * change (`updated_at`); see `stale`. */
function told(status, before = undefined, at = status.updated_at) {
  const merged = { ...before, ...status, toldAt: performance.now(), newsAt: at ?? 0 };
  // Who cancelled it is kept once known (a restarted server no longer knows it).
  if (before?.cancelled_by && !status.cancelled_by) merged.cancelled_by = before.cancelled_by;
  // Skipped stops stay shown after the tour ends (its last news has no progress any more).
  if (status.progress?.skipped?.length) merged.skipped = status.progress.skipped;
  return merged;
}

/** Whether news of a task (told at server time `at`) is older than what the page holds: it
 * gives another state than a change the server made later. A task can go back (in line again
 * after a robot had it: the way out of order for a while, staff taking it off a robot), so the
 * order of states says nothing; time does. A REST answer read before a task_event that came
 * first (or the reverse) must not undo it: a phone stayed "assigned to R1" while the task was
 * back in line (tests/web/test_busy_truth.py). */
function stale(before, status, at) {
  return Boolean(before && before.state !== status.state && (at ?? 0) < (before.newsAt ?? 0));
}

/** `status` (told at server time `at`) over what the page holds of it, unless it is stale. */
function update(status, at = status.updated_at) {
  const before = state.requests.get(status.id);
  if (!stale(before, status, at)) state.requests.set(status.id, told(status, before, at));
}

/** A told wait (seconds) minus the time since it was told: what the server estimates now,
 * until it tells another (it does when its estimate drifts from this countdown). Under a
 * minute to the nearest 10 s, so that a screen reader is not told a new number every second
 * (rounded up, 21 s left read "about 30 s"); under 5 s it is 0: "any moment now". */
function countdown(seconds, at) {
  if (seconds === null || seconds === undefined) return null;
  const left = Math.max(0, seconds - (performance.now() - at) / 1000);
  return left < 60 ? Math.round(left / 10) * 10 : left;
}

async function refreshRequests(ids) {
  for (const id of ids) {
    try {
      update(await api.get(`/api/tasks/${encodeURIComponent(id)}`));
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

/** The name of a point in the page's language (its id when the site no longer has it). */
function poiName(id) {
  return state.menu?.pois.find((x) => x.id === id)?.name ?? id ?? "";
}

/** Where the robot really is on a tour: the point it reported (the server names it), never a
 * stop counted in the tour as the site has it now (a live edit may have reordered it). */
function placeOf(progress) {
  return progress.name ?? poiName(progress.poi);
}

/** Today's coming public booked tours, names in the page's language (docs/visitor.md). */
async function loadNextTours() {
  const lang = state.menu?.lang;
  state.nextTours = (await api.get(`/api/bookings/next?limit=3${lang ? `&lang=${encodeURIComponent(lang)}` : ""}`)).tours;
}

function nextToursView() {
  const lines = nextTourLines(t, state.nextTours);
  if (!lines.length) return "";
  return html`<section class="next-tours" aria-labelledby="next-title">
    <h2 id="next-title">${t("next_tours")}</h2>
    <ul>${lines.map((l) => html`<li><strong>${l.name}</strong>: ${l.line}</li>`)}</ul>
  </section>`;
}

async function reload() {
  try {
    await loadMenu();
    // This device's live requests (after a reload or a server restart), then the ones we follow.
    for (const status of await api.get("/api/visitor/requests")) update(status);
    await refreshRequests([...state.requests.keys()]);
    for (const status of state.requests.values()) state.labels.set(status.id, labelOf(status));
    await loadEmergency();
    await loadNextTours();
    if (state.errorFrom !== "action") showError("", "");
  } catch (err) {
    // Before any texts (a refused token at the first load): say it in the page's language.
    if (!state.texts) state.texts = await loadTexts(state.lang ?? "en");
    showError(describe(err), "load");
    draw();
    return err;
  }
  draw();
  return null;
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
  if (state.slow) params.pace = "slow";
  if (state.stepFree) params.step_free = true;
  try {
    const status = await api.post("/api/tasks", { kind: KIND[kind], params });
    state.requests.set(status.id, told(status));
    // News of it that came before this answer: newer when the server sent it after the task's
    // last change in the answer (further along, or back in line).
    const first = early.get(status.id);
    early.delete(status.id);
    if (first && first.payload.state !== status.state) update({ ...first.payload, id: status.id }, first.at);
    state.labels.set(status.id, item.name);
    state.current = status.id;
    state.view = "request";
    state.confirming = false;
    remember();
  } catch (err) {
    if (err instanceof ApiError && err.reason === "emergency") {
      // Refused for a fire alarm: the server's words (in this language), the evacuation screen.
      showError(typeof err.detail === "string" ? err.detail : t("evacuation_no_requests"), "action");
      await loadEmergency().catch(() => {});
    } else showError(describe(err), "action");
  } finally {
    state.busy = false;
  }
  draw();
  focusHeading();
}

async function cancel(id = state.current) {
  try {
    state.requests.set(id, told(await api.post(`/api/tasks/${encodeURIComponent(id)}/cancel`, { reason: "cancelled by the visitor" }), state.requests.get(id)));
    showError("", "");
  } catch (err) {
    showError(describe(err), "action");
  }
  state.confirming = false;
  state.cutOff.delete(id);
  remember();
  draw();
}

/** The answer to the offer after an alarm: go on (the request keeps its place) or drop it. */
async function answerOffer(id, goOn) {
  if (!goOn) return cancel(id);
  state.cutOff.delete(id);
  state.current = id;
  state.view = "request";
  remember();
  draw();
  focusHeading();
}

/** A slower tour, or the usual pace again: the menu's lengths follow. */
async function toggleSlow() {
  state.slow = !state.slow;
  showError("", "");
  await reload();
}

async function toggleStepFree() {
  state.stepFree = !state.stepFree;
  showError("", "");
  await reload();
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
  requestAnimationFrame(() => /** @type {HTMLElement | null} */ (app.querySelector("h1, h2"))?.focus());
}

// --- views --------------------------------------------------------------------------------------

function picture(media, name) {
  const first = (media ?? []).find((m) => m.url && !state.brokenPictures.has(m.url));
  if (!first) return html`<div class="picture placeholder" role="img" aria-label=${t("picture_missing")}><svg aria-hidden="true" viewBox="0 0 24 24" width="56" height="56" fill="none" stroke="currentColor" stroke-width="1.5" stroke-linejoin="round"><rect x="3" y="4" width="18" height="16" rx="2"/><circle cx="9" cy="10" r="2"/><path d="M3 18l5-5 4 4 3-3 6 6"/></svg></div>`;
  const broken = () => {
    state.brokenPictures.add(first.url);
    draw();
  };
  return html`<img class="picture" src=${first.url} alt=${name} @error=${broken}>`;
}

function serviceLine(estimate) {
  if (!estimate) return "";
  if (estimate.service === "unavailable") return t("service_unavailable");
  if (estimate.service === "held_up") return t("service_held_up");
  if (estimate.service === "paused") return t("service_paused"); // staff paused: no countdown
  if (estimate.service === "busy") {
    const wait = countdown(estimate.eta_s, state.menuAt);
    if (wait === null) return t("service_busy_unknown");
    return wait > 0 ? t("service_busy", { t: state.texts.duration(wait) }) : t("service_busy_now");
  }
  return t("service_available");
}

/** The stops a visitor will get: step-free, those only steps lead to are left out (and said). */
function stopsFact(tour) {
  const skipped = state.stepFree ? (tour.step_free_skips?.length ?? 0) : 0;
  const n = tour.stops.length - skipped;
  return skipped ? t("stops_step_free", { n, k: skipped }) : t("stops", { n });
}

function card(kind, item) {
  const estimate = item.estimate;
  const unavailable = estimate?.service === "unavailable";
  const stepsOnly = kind === "poi" && state.stepFree && item.steps_only; // refused: said why
  const facts = [];
  if (kind === "tour") facts.push(stopsFact(item));
  // A point's length is its explanation there (the walk to it is the wait), not a tour's.
  const slow = state.menu.pace === "slow";
  const length = kind === "tour" ? (slow ? "tour_length_slow" : "tour_length") : (slow ? "point_length_slow" : "point_length");
  if (estimate?.duration_s) facts.push(t(length, { t: state.texts.duration(estimate.duration_s) }));
  const media = kind === "tour" ? item.stops.flatMap((s) => s.media) : item.media;
  const id = `${kind}-${item.id}`;
  const fb = item.fallback ?? {};
  return html`<article class="card" aria-labelledby=${`${id}-name`}>
    ${picture(media, item.name)}
    <div class="card-body">
      <h3 id=${`${id}-name`} lang=${fb.name ?? nothing}>${item.name}</h3>
      ${item.description ? html`<p lang=${fb.description ?? nothing}>${item.description}</p>` : ""}
      ${fallbackNote(fb)}
      <p class="muted">${facts.join(" · ")}</p>
      ${kind === "tour" && state.stepFree && item.step_free_skips?.length
        ? html`<p class="skips">${t("step_free_skips", { names: item.step_free_skips.map(poiName).join(", ") })}</p>` : ""}
      ${stepsOnly ? html`<p class="skips steps-only" id=${`${id}-steps`}>${t("steps_only")}</p>` : ""}
      ${stepsOnly ? "" : html`<p class=${`wait ${estimate?.service ?? ""}`} id=${`${id}-wait`}>${serviceLine(estimate)}</p>`}
      <button class="big" ?disabled=${unavailable || stepsOnly || state.busy}
        aria-describedby=${`${id}-name ${stepsOnly ? `${id}-steps` : `${id}-wait`}`}
        @click=${() => request(kind, item)}>${t(kind === "tour" ? "request_tour" : "request_point")}</button>
    </div>
  </article>`;
}

/** A tick on a button that is on (a chosen language, a slower tour): not told by colour
 * alone (aria-pressed tells screen readers). */
const on = (value) => (value ? html`<span class="tick" aria-hidden="true">✓ </span>` : "");

/** A text the site has not translated into the page's language is shown in the site's own
 * language (marked with `lang` for screen readers), and the visitor is told so. */
function fallbackNote(fallback) {
  const langs = [...new Set(Object.values(fallback ?? {}))];
  if (!langs.length) return "";
  return html`<p class="fallback">${langs.map((lang) => t("text_fallback", { language: names.get(lang) ?? lang })).join(" ")}</p>`;
}

function languagePicker() {
  const langs = state.menu.languages;
  if (langs.length < 2) return "";
  return html`<div class="languages" role="group" aria-label=${t("choose_language")}>
    ${langs.map((lang) => html`<button class="secondary" lang=${lang} aria-pressed=${String(lang === state.menu.lang)}
      @click=${() => chooseLanguage(lang)}>${on(lang === state.menu.lang)}${names.get(lang) ?? lang}</button>`)}
  </div>`;
}

/** "Slower tour" and "Step-free only": toggles; on, the lengths shown and the requests made
 * are at the slow pace, and tours keep off steps. */
function paceToggle() {
  const slow = state.menu.pace === "slow";
  return html`<div class="pace-option">
    <button class="secondary" aria-pressed=${String(slow)} aria-describedby="pace-help" ?disabled=${state.busy}
      @click=${toggleSlow}>${on(slow)}${t("slower_tour")}</button>
    <p class="muted" id="pace-help">${t("slower_tour_help")}</p>
  </div>
  <div class="pace-option">
    <button class="secondary" aria-pressed=${String(state.stepFree)} aria-describedby="step-free-help"
      ?disabled=${state.busy} @click=${toggleStepFree}>${on(state.stepFree)}${t("step_free")}</button>
    <p class="muted" id="step-free-help">${t("step_free_help")}</p>
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
    ${paceToggle()}
    <p class=${`service ${menu.service}`} role="status">${serviceLine({ service: menu.service, eta_s: menu.tours[0]?.estimate?.eta_s ?? null })}</p>
    ${errorBox()}
    ${nextToursView()}
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

function statusLines(r) {
  const lines = [];
  const robot = r.robot ?? "";
  const progress = r.progress;
  const point = r.kind === "go_to_poi";
  const arrival = countdown(r.arrival_s, r.toldAt);
  const handover = r.handover && r.handover.arrived_after_s == null ? r.handover : null; // handover
  if (handover && r.state === "queued") lines.push(t("handover_waiting", { robot: handover.from_robot, i: handover.stop }));
  if (handover && handover.robot && (r.state === "assigned" || r.state === "running")) {
    lines.push(arrival !== null && arrival > 0
      ? t("handover_arrival", { robot, i: handover.stop, t: state.texts.duration(arrival) })
      : t("handover", { robot, i: handover.stop }));
    return lines;
  }
  if (r.state === "queued" && r.trouble) {
    // Its way is out of order for a while (a jammed door, a stuck lift): no time promised.
    lines.push(t("state_trouble_wait", { why: skipReason(t, r.trouble.why) }));
    if (r.queue_position) lines.push(t("state_queued", { n: r.queue_position }));
  } else if (r.state === "queued") {
    if (r.service === "unavailable") lines.push(t("state_unavailable"));
    else if (r.service === "paused") {
      // Staff paused the fleet: nothing starts until they resume, so no countdown.
      if (r.queue_position) lines.push(t("state_queued", { n: r.queue_position }));
      lines.push(t("state_paused"));
    } else {
      if (r.queue_position) lines.push(t("state_queued", { n: r.queue_position }));
      const wait = countdown(r.eta_s, r.toldAt);
      if (r.service === "held_up") lines.push(t("service_held_up"));
      else if (wait === null) lines.push(t("service_busy_unknown"));
      // A wait counted down to nothing while still in line: no "in about 0 s".
      else lines.push(wait > 0 ? t("state_wait", { t: state.texts.duration(wait) }) : t("state_wait_now"));
    }
  } else if (r.state === "assigned" || r.state === "running") {
    if (point) {
      const place = poiName(r.params?.poi);
      if (progress?.stage === "arrived" || progress?.stage === "explained") lines.push(t("state_point_arrived", { robot, place }));
      else if (r.service === "held_up") lines.push(t("state_held_up", { robot }));
      else if (arrival !== null && arrival > 0) lines.push(t("state_point_on_its_way", { robot, place, t: state.texts.duration(arrival) }));
      else lines.push(t("state_point_going", { robot, place }));
    } else if (!progress || progress.index === 0) {
      lines.push(t("state_assigned", { robot }));
      if (r.service === "held_up") lines.push(t("state_held_up", { robot }));
      else if (arrival !== null) lines.push(arrival > 0 ? t("state_on_its_way", { robot, t: state.texts.duration(arrival) }) : t("state_on_its_way_now", { robot }));
      // No figure from the server (the robot is later than it foretold): on its way, no countdown.
      else if (r.arrival_s === null && r.service === "available") lines.push(t("state_on_its_way_nofigure", { robot }));
    } else {
      const place = placeOf(progress);
      if (progress.index === 1 && progress.stage === "arrived") lines.push(t("state_arrived", { robot, place }));
      const explained = progress.stage === "explained";
      lines.push(t(explained ? "state_explained" : "state_progress", { i: progress.index, n: progress.total, place }));
      // After a stop's explanation the robot asks on its screen whether to go on, then walks on.
      // Once the robot is on its way again (the server saw it move: its visitors said yes).
      if (explained && progress.index < progress.total) lines.push(t(progress.going ? "state_leading_on" : "state_next_stop", { robot }));
      if (r.service === "held_up") lines.push(t("state_held_up", { robot }));
    }
  } else if (r.state === "done") lines.push(point ? t("state_point_done", { robot, place: poiName(r.params?.poi) }) : t("state_done"));
  else if (r.state === "failed") lines.push(t("state_failed", { reason: r.reason }));
  else if (r.service === "withdrawn") lines.push(t("state_withdrawn"));
  else if (r.cancelled_by === "staff") lines.push(t(point ? "state_cancelled_staff_point" : "state_cancelled_staff_tour"));
  else lines.push(t("state_cancelled"));
  if (FINAL.has(r.state)) lines.push(...endedAt(r));
  return lines;
}

/** How far a tour that ended got (the server keeps its last progress): said unless it ended
 * done at its last stop. */
function endedAt(r) {
  const p = r.progress;
  // A visit to one point that ended after its robot had got there (kept by the server).
  if (r.kind === "go_to_poi") return p?.index && r.state !== "done" ? [t("state_point_reached", { robot: r.robot ?? "", place: poiName(r.params?.poi) })] : [];
  if (r.kind !== "tour" || !p?.index) return [];
  // Done with every stop after its last one skipped (closed, only steps): it went to its end.
  const skipped = new Set((r.skipped ?? p.skipped ?? []).map((k) => k.index));
  let last = p.total;
  while (last > p.index && skipped.has(last)) last -= 1;
  if (r.state === "done") return p.index < last ? [t("state_ended_at", { i: p.index, n: p.total, place: placeOf(p) })] : [];
  return [t("state_got_to", { i: p.index, n: p.total, place: placeOf(p) })];
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
    ${paceLine(r)}
    ${errorBox()}
    <div class=${`request-state ${r.state}`}>
      ${statusLines(r).map((line) => html`<p>${line}</p>`)}
    </div>
    ${r.skipped?.length ? html`<section class="skipped" aria-labelledby="skipped-title"><h3 id="skipped-title">${t("skipped_title")}</h3>
      <ul>${skippedLines(t, r.skipped, placeOf).map((line) => html`<li>${line}</li>`)}</ul></section>` : ""}
    ${captionView(r)}
    ${signVideo(r)}
    ${progress && progress.total ? html`<label class="progress">${t("progress_label")}
      <progress max=${progress.total} value=${progress.index}>${progress.index} / ${progress.total}</progress></label>` : ""}
    <div class="actions">
      ${final ? "" : state.confirming
        ? html`<button class="big danger" @click=${() => cancel()}>${t("cancel_confirm")}</button>
               <button class="big secondary" @click=${() => { state.confirming = false; draw(); }}>${t("keep")}</button>`
        : html`<button class="big secondary" @click=${() => { state.confirming = true; draw(); }}>${t("cancel")}</button>`}
      <button class="big" @click=${backToStart}>${final ? t(r.kind === "go_to_poi" ? "new_request_point" : "new_request") : t("back")}</button>
    </div>`;
}

/** A slower tour says so, with how long it takes from the first stop (the server counts the
 * slower pace in it). */
function paceLine(r) {
  const lines = [];
  if (r.params?.pace === "slow") lines.push(r.duration_s ? t("state_slower", { t: about(r.duration_s) }) : t("state_slower_unknown"));
  if (r.params?.step_free) lines.push(t(r.params.tour ? "state_step_free" : "state_step_free_visit"));
  return lines.map((line) => html`<p class="pace">${line}</p>`);
}

/** The stop's text in sign language, where the site has a video of it: during the stop of a
 * tour (the point its robot reported), until the tour moves on. */
function signVideo(r) {
  const poi = !FINAL.has(r.state) && r.progress?.index ? r.progress.poi : null;
  const item = poi ? state.menu?.pois.find((x) => x.id === poi) : null;
  if (!item?.sign_video) return "";
  return html`<section class="sign-video" aria-labelledby="sign-title">
    <h3 id="sign-title">${t("sign_video", { name: item.name })}</h3>
    <video src=${item.sign_video} controls muted autoplay loop playsinline aria-labelledby="sign-title"></video>
  </section>`;
}

/** Captions: what the visitor's robot is saying now, in the tour's language, while it says it
 * (speech_started/speech_ended of that robot, docs/visitor.md "Captions"). Not a live region:
 * the robot is heard; the announcer says the state changes. */
function captionView(r) {
  const said = r.robot && !FINAL.has(r.state) ? state.speaking.get(r.robot) : null;
  if (!said || !said.text) return "";
  if (!said.shown_at) {
    said.shown_at = Date.now();
    captionsShown.push({ started_at: said.started_at, shown_at: said.shown_at, text: said.text, lang: said.lang });
    if (captionsShown.length > 50) captionsShown.shift();
  }
  return html`<section class="captions" aria-labelledby="captions-title">
    <h3 id="captions-title" class="sr-only">${t("captions")}</h3>
    <p class="caption" lang=${said.lang ?? state.lang}>${said.text}</p>
  </section>`;
}

/** The site's words for the alarm in the page's language (its default language's otherwise). */
function alarmWords() {
  const words = state.emergency?.words ?? {};
  return words[state.menu.lang] ?? words[state.menu.default_language] ?? t("evacuation_default");
}

/** While an alarm lasts: the site's words, no request possible, a cut-off request's fate. */
function evacuationView() {
  const cut = [...state.cutOff].map((id) => state.requests.get(id)).filter((r) => r && !FINAL.has(r.state));
  return html`<section class="evacuation" aria-labelledby="evacuation-title">
      <header class="visitor-top">
        <h1 id="evacuation-title" tabindex="-1">${t("evacuation_title")}</h1>
        ${languagePicker()}
      </header>
      <p class="evacuation-words" role="alert">${alarmWords()}</p>
      <p>${t("evacuation_no_requests")}</p>
      ${cut.map((r) => html`<p class="notice">${t("evacuation_cut_off", { name: state.labels.get(r.id) ?? labelOf(r) })}</p>`)}
      ${state.error && state.error !== alarmWords() ? errorBox() : ""}
    </section>`;
}

/** After the alarm: a request it cut off is offered again, in its place in line. */
function offerView(r) {
  const name = state.labels.get(r.id) ?? labelOf(r);
  return html`<header class="visitor-top">
      <h1 tabindex="-1">${t("offer_title")}</h1>
      ${languagePicker()}
    </header>
    ${errorBox()}
    <div class="request-state" role="status">
      <p>${t("offer_text", { name })}</p>
      ${statusLines(r).map((line) => html`<p>${line}</p>`)}
    </div>
    <div class="actions">
      <button class="big" @click=${() => answerOffer(r.id, true)}>${t("offer_keep")}</button>
      <button class="big secondary" @click=${() => answerOffer(r.id, false)}>${t("offer_drop")}</button>
    </div>`;
}

function offered() {
  if (alarm()) return null;
  for (const id of state.cutOff) {
    const r = state.requests.get(id);
    if (r && !FINAL.has(r.state)) return r;
  }
  return null;
}

const names = new Map();

function draw() {
  if (!app.dataset.drawn) {
    app.textContent = ""; // the "Loading…" placeholder, before lit-html owns the container
    app.dataset.drawn = "1";
  }
  if (!state.texts) return;
  if (!state.menu) {
    app.setAttribute("aria-busy", "false");
    render(html`${errorBox()}`, app);
    return;
  }
  app.setAttribute("aria-busy", "false");
  const offer = offered();
  document.body.classList.toggle("alarm", alarm());
  if (alarm()) render(evacuationView(), app);
  else if (offer) render(offerView(offer), app);
  else render(state.view === "request" ? requestView() : startView(), app);
  announce();
}

const announcer = document.getElementById("announcer");
let announced = "";

/** Screen readers hear each change of the request's state (place in line, the robot coming,
 * stop N of M, the end) from one live region that is always in the page: a region inserted
 * with its text is not read, and the request's view is drawn anew. Said once per change, not
 * at every countdown tick. */
function announce() {
  const r = state.view === "request" && !alarm() && !offered() ? state.requests.get(state.current) : null;
  const p = r?.progress;
  const key = r ? JSON.stringify([r.id, r.state, r.queue_position, r.robot, p?.index, p?.stage, p?.going, r.service, r.cancelled_by, r.trouble?.why]) : "";
  if (key === announced) return;
  announced = key;
  announcer.textContent = r ? statusLines(r).join(" ") : "";
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
      state.slow = false;
      state.stepFree = false;
      // The next visitor is another device: the last one's requests are no longer listed here
      // (and can no longer be cancelled from here); they stay with the server.
      device = deviceId(true);
      state.requests.clear();
      state.labels.clear();
      state.cutOff.clear();
      sessionStorage.removeItem(STORE);
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
  for (const id of saved.cutOff ?? []) state.cutOff.add(id);
  for (const id of saved.ids ?? []) state.requests.set(id, { id, state: "queued", params: {} });
  if (!token) {
    state.texts = await loadTexts(state.lang ?? "en");
    state.error = t("error_no_token");
    draw();
    return;
  }
  await live();
}

/** The first read, then live over the hub. Until the first read succeeds the page says why
 * and tries again every 5 s; a refused token (401/403) is said once and stays. */
async function live() {
  const failed = await reload();
  if (!state.menu) {
    const status = failed instanceof ApiError ? failed.status : 0;
    if (status !== 401 && status !== 403) setTimeout(live, 5000);
    return;
  }
  for (const lang of state.menu.languages) names.set(lang, (await loadTexts(lang)).name);
  draw();
  const hub = new HubClient({ token }).start();
  hub.subscribe("task_event", "visitor_service", "emergency_changed", "speech_started", "speech_ended", "next_tours", "site_published");
  // A new site version is live (tours, points, names, pictures): read the menu again at once.
  hub.on("site_published", async () => {
    try {
      await loadMenu();
      await loadNextTours();
    } catch {
      /* the next event or the reconnect's reload reads it again */
    }
    draw();
  });
  // The booked tours of today changed (booked, moved, cancelled, one started): read them again.
  hub.on("next_tours", async () => {
    try {
      await loadNextTours();
    } catch {
      /* the reconnect's reload reads them again */
    }
    draw();
  });
  // What each robot is saying: the request's robot's words are its captions.
  hub.on("speech_started", (message) => {
    const p = message.payload;
    state.speaking.set(message.source, { text: p.text, lang: p.lang, started_at: message.timestamp });
    if (state.requests.get(state.current)?.robot === message.source) draw();
  });
  hub.on("speech_ended", (message) => {
    if (state.speaking.get(message.source)?.text !== message.payload.text) return;
    state.speaking.delete(message.source);
    if (state.requests.get(state.current)?.robot === message.source) draw();
  });
  hub.on("task_event", (message) => {
    const p = message.payload;
    refreshMenuSoon();
    const known = state.requests.get(p.task_id);
    if (!known) {
      // Not ours (the server tells a device's REST calls only its own), or ours before our
      // request's answer: kept a while for request() to look at.
      early.set(p.task_id, { payload: p, at: message.timestamp });
      if (early.size > EARLY_MAX) early.delete(early.keys().next().value);
      return;
    }
    update({ ...p, id: p.task_id }, message.timestamp);
    if (p.state === "queued" && p.reason === CUT_OFF) markCutOff([p.task_id]);
    if (FINAL.has(p.state)) remember();
    draw();
  });
  // A fire alarm starts or ends: the evacuation screen, then the offer (docs/emergency.md).
  hub.on("emergency_changed", async (message) => {
    const was = alarm();
    state.emergency = { ...(state.emergency ?? {}), ...message.payload };
    try {
      await loadEmergency();
    } catch {
      /* the reconnect's reload reads it again */
    }
    if (was && !alarm() && state.errorFrom === "action") showError("", "");
    refreshMenuSoon();
    draw();
    if (was !== alarm()) focusHeading();
  });
  // What a new request would be told changed (a robot free, a jam): read the menu again.
  hub.on("visitor_service", () => refreshMenuSoon());
  hub.addEventListener("status", () => {
    banner.dataset.status = hub.status;
    banner.textContent = hub.status === "open" ? "" : t(hub.status === "refused" ? "error_token" : "connection_lost");
  });
  // Told waits count down on the page between the server's news.
  setInterval(draw, 1000);
  // After every (re)connect, e.g. a server restart, the true state comes from REST.
  hub.addEventListener("connect", () => reload());
}

start();
