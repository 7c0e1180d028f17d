// The robot's touch screen: the visitor panel's look and language files (/lib, /lang, /visitor
// served by the robot itself), tours and points to request, the current explanation with its
// picture, "continue the tour?" with a visible countdown, and the robot's state; while staff
// pause the fleet, that they did (as the phone says it). During a fire alarm: the evacuation
// screen, the site's words in the screen's language (docs/emergency.md).
import { html, nothing, render } from "/vendor/lit-html/lit-html.js";
import { loadTexts } from "/lib/i18n.js";
import { nextTourLines } from "/lib/nexttours.js";
import { skippedLines } from "/lib/skipped.js";

const app = document.getElementById("app");
const state = { screen: null, texts: null, chosen: null, message: "", broken: new Set(), now: Date.now(), large: false, contrast: false, slow: false, stepFree: false };
const t = (key, vars) => state.texts.t(key, vars);
/** language tag -> its name in itself, for the picker */
const names = new Map();

const banner = document.getElementById("connection");

const PROBLEMS = {
  connection_lost: "Connection lost: reconnecting…",
  screen_error: "The robot's screen could not be read: trying again…",
};

/** Shows or hides the banner: "connection lost" (the robot's agent restarting) or, when the
 * agent answers but not with the screen (an HTTP error), "screen_error"; English before any
 * texts. */
function showReachable(reachable, problem = "connection_lost") {
  banner.dataset.status = reachable ? "open" : problem === "connection_lost" ? "reconnecting" : "error";
  banner.textContent = reachable ? "" : state.texts?.t(problem) ?? PROBLEMS[problem];
}

/** POST to the agent; a network failure answers status 0 instead of throwing. */
async function post(path, body) {
  let r;
  try {
    r = await fetch(path, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  } catch {
    showReachable(false);
    return { ok: false, status: 0, data: {} };
  }
  let data = {};
  try {
    data = await r.json();
  } catch {
    data = {};
  }
  return { ok: r.ok, status: r.status, data };
}

const RETRY_MS = 2000;
let retry = null;

/** Reads the whole screen again; while the agent cannot be reached, the banner says so. */
async function refresh() {
  const lang = state.chosen ? `?lang=${encodeURIComponent(state.chosen)}` : "";
  let r;
  try {
    r = await fetch(`/api/screen${lang}`);
  } catch {
    showReachable(false); // the WebSocket's reconnect reads the screen again
    return;
  }
  let screen;
  try {
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    screen = await r.json();
  } catch {
    showReachable(false, "screen_error");
    clearTimeout(retry);
    retry = setTimeout(refresh, RETRY_MS); // the agent answers: ask again (a push may not come)
    return;
  }
  showReachable(true);
  // A running tour speaks its visitor's language: the screen follows it.
  if (screen.tour_lang && screen.tour_lang !== screen.lang) {
    state.chosen = screen.tour_lang;
    return refresh();
  }
  if (screen.task && !state.screen?.task) state.message = ""; // the request became a tour
  if (!screen.task && state.screen?.task) state.large = state.contrast = state.slow = state.stepFree = false; // the next visitor
  state.screen = screen;
  if (!state.texts || state.texts.lang !== screen.lang) state.texts = await loadTexts(screen.lang);
  if (!names.size) for (const lang of screen.languages) names.set(lang, (await loadTexts(lang)).name);
  document.documentElement.lang = screen.lang;
  draw();
}

async function ask(kind, item) {
  const body = kind === "tour" ? { kind, tour: item.id } : { kind, poi: item.id };
  body.lang = state.screen.lang;
  if (state.slow) body.pace = "slow";
  if (state.stepFree) body.step_free = true;
  const r = await post("/api/request", body);
  if (r.ok) state.message = r.data.queued_offline ? t("request_queued_offline") : t("requested");
  else if (r.status === 0) state.message = t("error_network");
  else if (r.data.reason === "emergency") state.message = r.data.detail; // the site's words
  else state.message = r.status === 503 ? t("link_down_refuse") : t("error_server", { detail: r.data.detail ?? r.status });
  draw();
}

async function answer(value) {
  await post("/api/answer", { answer: value });
}

function picture(media, name) {
  const first = (media ?? []).find((m) => m.url && !state.broken.has(m.url));
  if (!first) return html`<div class="picture placeholder" role="img" aria-label=${t("picture_missing")}><svg aria-hidden="true" viewBox="0 0 24 24" width="56" height="56" fill="none" stroke="currentColor" stroke-width="1.5" stroke-linejoin="round"><rect x="3" y="4" width="18" height="16" rx="2"/><circle cx="9" cy="10" r="2"/><path d="M3 18l5-5 4 4 3-3 6 6"/></svg></div>`;
  return html`<img class="picture" src=${first.url} alt=${name} @error=${() => { state.broken.add(first.url); draw(); }}>`;
}

function questionView(q) {
  if (!q) return "";
  const left = Math.max(0, Math.ceil(q.deadline_at - state.now / 1000));
  return html`<section class="touch-question" role="alertdialog" aria-labelledby="question-text" aria-describedby="countdown">
    <h2 id="question-text">${t("question")}</h2>
    <p class="countdown" id="countdown" role="timer">${t("time_left", { s: left })}</p>
    <div class="actions">
      <button class="big" @click=${() => answer("yes")}>${t("yes")}</button>
      <button class="big danger" @click=${() => answer("no")}>${t("no")}</button>
    </div>
  </section>`;
}

function stateView(s) {
  const robot = s.state ?? {};
  // While staff pause the fleet an idle robot starts nothing: it is not "Ready".
  const reported = robot.mode ?? "idle";
  const mode = reported === "idle" && s.service === "paused" && !s.task ? "paused" : reported;
  const link = s.link ?? {};
  const battery = robot.battery === undefined ? "" : `${Math.round(robot.battery * 100)} %`;
  return html`${link.up === false
      ? html`<p class="link-down" role="alert">${t(link.offline_requests === "refuse" ? "link_down_refuse" : "link_down_queue")}</p>`
      : ""}
    <p class="touch-state" role="status">
      <span>${t(`mode_${mode}`)}</span>
      ${s.going && !s.question ? html`<span>${t("going_next")}</span>` : ""}
      ${battery ? html`<span>${t("battery", { p: battery })}</span>` : ""}
    </p>`;
}

function skippedView(s) {
  if (!s.skipped?.length) return "";
  return html`<section class="skipped" aria-labelledby="skipped-title"><h3 id="skipped-title">${t("skipped_title")}</h3>
    <ul>${skippedLines(t, s.skipped, (k) => k.name ?? k.poi).map((line) => html`<li>${line}</li>`)}</ul></section>`;
}

/** The last captions shown, {started_at (Unix s), shown_at (Unix ms), text, lang}: how late each
 * came, for tests and for a look from the browser's console. */
const captionsShown = [];
window.captionsShown = captionsShown;

/** Captions: the words the robot is saying now, in their language, while it says them. The
 * page notes when each utterance first showed (data-shown-at, Unix ms) next to the time its
 * speech started (data-started-at): tests compare the two. Not a live region: the explanation
 * above is one already, and a screen reader would read the words twice. */
function captionView(s) {
  const said = s.speaking;
  if (!said || !said.text) return "";
  if (state.caption?.started_at !== said.started_at) {
    state.caption = { started_at: said.started_at, shown_at: Date.now(), text: said.text, lang: said.lang };
    captionsShown.push(state.caption);
    if (captionsShown.length > 50) captionsShown.shift();
  }
  return html`<section class="captions" aria-labelledby="captions-title">
    <h2 id="captions-title" class="sr-only">${t("captions")}</h2>
    <p class="caption" lang=${said.lang ?? s.lang} data-started-at=${Math.round(said.started_at * 1000)}
      data-shown-at=${state.caption.shown_at}>${said.text}</p>
  </section>`;
}

/** A tour's button; with "Step-free only" on, the stops a step-free tour skips are said on it. */
function tourButton(s, tour, refused) {
  const skips = state.stepFree ? tour.step_free_skips ?? [] : [];
  const names = skips.map((id) => s.pois.find((p) => p.id === id)?.name ?? id).join(", ");
  return html`<button class="big" ?disabled=${refused} @click=${() => ask("tour", tour)}><span
    lang=${tour.fallback?.name ?? nothing}>${tour.name}</span>${skips.length ? html`<span class="steps-only">${t("step_free_skips", { names })}</span>` : ""}</button>`;
}

/** A point's "take me there": with "Step-free only" on, a point only steps lead to is refused
 * and says why on the button itself (read with its name; `aria-disabled`, not `disabled`, so
 * the reason keeps its full contrast). */
function pointButton(poi, refused) {
  const stepsOnly = Boolean(state.stepFree && poi.steps_only);
  const go = () => { if (!stepsOnly) ask("go_to_poi", poi); };
  return html`<button class="big secondary" ?disabled=${refused} aria-disabled=${String(stepsOnly)} @click=${go}><span
    lang=${poi.fallback?.name ?? nothing}>${poi.name}</span>${stepsOnly ? html`<span class="steps-only">${t("steps_only")}</span>` : ""}</button>`;
}

/** Before the first stop: the task the robot is starting, never the idle invitation. */
function startingText(s) {
  if (!s.task) return t("touch_idle");
  const tour = s.task.tour ? s.tours.find((x) => x.id === s.task.tour) : null;
  return tour ? t("touch_tour_starting", { tour: tour.name }) : t("touch_on_the_way");
}

function nowView(s) {
  const e = s.explanation;
  if (!e) return html`<p>${startingText(s)}</p>${skippedView(s)}`;
  return html`<div class="touch-now">
    ${picture(e.media, e.name)}
    <div>
      ${e.index ? html`<p class="muted">${t("state_progress", { i: e.index, n: e.total, place: e.name })}</p>` : html`<h3>${e.name}</h3>`}
      <p class="explanation" aria-live="polite" lang=${e.text_lang ?? nothing}>${e.text}</p>
      ${e.sign_video ? html`<video class="sign-video" src=${e.sign_video} controls muted autoplay loop playsinline
        aria-label=${t("sign_video", { name: e.name })}></video>` : ""}
      ${e.text_lang && e.text_lang !== s.lang ? html`<p class="fallback">${t("text_fallback", { language: names.get(e.text_lang) ?? e.text_lang })}</p>` : ""}
    </div>
  </div>${skippedView(s)}`;
}

/** While a fire alarm lasts: the site's words, what the robot does, no request. */
function alarmView(s) {
  const evacuation = s.alarm.evacuation;
  return html`<section class="evacuation" aria-labelledby="evacuation-title">
    <header class="visitor-top">
      <h1 id="evacuation-title">${t("evacuation_title")}</h1>
      ${languages(s)}
    </header>
    <p class="evacuation-words" role="alert">${s.alarm.words || t("evacuation_default")}</p>
    ${evacuation ? html`<p class="touch-state" role="status">${t(`evacuation_robot_${evacuation}`)}</p>` : ""}
    <p>${t("evacuation_no_requests")}</p>
  </section>`;
}

/** A tick on a toggle that is on: its state is not told by colour alone (aria-pressed tells
 * screen readers). */
const on = (value) => (value ? html`<span aria-hidden="true">✓ </span>` : "");

/** Larger text, high contrast and a slower tour, for this visitor (back to the defaults when
 * the tour ends). A slower tour is asked for with the request; during one it is shown on. */
function viewOptions(s) {
  const toggle = (key) => () => { state[key] = !state[key]; draw(); };
  const slow = s.task ? s.task.pace === "slow" : state.slow;
  const stepFree = s.task ? Boolean(s.task.step_free) : state.stepFree;
  return html`<div class="view-options" role="group" aria-label=${t("view_options")}>
    <button class="secondary" aria-pressed=${String(state.large)} @click=${toggle("large")}>${on(state.large)}${t("larger_text")}</button>
    <button class="secondary" aria-pressed=${String(state.contrast)} @click=${toggle("contrast")}>${on(state.contrast)}${t("high_contrast")}</button>
    <button class="secondary" aria-pressed=${String(slow)} ?disabled=${Boolean(s.task)} aria-describedby="pace-help"
      @click=${toggle("slow")}>${on(slow)}${t("slower_tour")}</button>
    <button class="secondary" aria-pressed=${String(stepFree)} ?disabled=${Boolean(s.task)} aria-describedby="step-free-help"
      @click=${toggle("stepFree")}>${on(stepFree)}${t("step_free")}</button>
    <p class="sr-only" id="pace-help">${t("slower_tour_help")}</p>
    <p class="sr-only" id="step-free-help">${t("step_free_help")}</p>
  </div>`;
}

/** The language buttons; during a task the screen follows its visitor's language (a tap would
 * change nothing), so they are off and say why. */
function languages(s) {
  if (s.languages.length < 2) return "";
  const fixed = Boolean(s.task && s.tour_lang);
  return html`<div class="languages" role="group" aria-label=${t("choose_language")}>
    ${s.languages.map((lang) => html`<button class="secondary" lang=${lang} aria-pressed=${String(lang === s.lang)}
      ?disabled=${fixed} aria-describedby=${fixed ? "lang-help" : nothing}
      @click=${() => { state.chosen = lang; refresh(); }}>${on(lang === s.lang)}${names.get(lang) ?? lang}</button>`)}
    ${fixed ? html`<p class="muted" id="lang-help">${t("touch_lang_of_tour")}</p>` : ""}</div>`;
}

function draw() {
  const s = state.screen;
  if (!s || !state.texts) return;
  app.setAttribute("aria-busy", "false");
  if (!app.dataset.drawn) {
    app.textContent = ""; // the "Loading…" placeholder, before lit-html owns the container
    app.dataset.drawn = "1";
  }
  document.body.classList.toggle("alarm", Boolean(s.alarm));
  document.body.classList.toggle("large-text", state.large);
  document.body.classList.toggle("high-contrast", state.contrast);
  if (s.alarm) {
    render(alarmView(s), app);
    return;
  }
  const refused = s.link?.up === false && s.link?.offline_requests === "refuse";
  render(html`<header class="visitor-top">
      <h1>${t("touch_title", { robot: s.robot })}</h1>
      ${languages(s)}
      ${viewOptions(s)}
    </header>
    ${stateView(s)}
    ${s.service === "paused" && !s.task ? html`<p class="notice" role="status">${t("service_paused")}</p>` : ""}
    ${captionView(s)}
    ${s.task?.pace === "slow" ? html`<p class="pace">${t("state_slower_unknown")}</p>` : ""}
    ${s.task?.step_free ? html`<p class="pace">${t(s.task.tour ? "state_step_free" : "state_step_free_visit")}</p>` : ""}
    ${s.task?.handover ? html`<p class="notice" role="status">${t("handover", { robot: s.robot, i: s.task.handover.stop })}</p>` : ""}
    ${questionView(s.question)}
    <section aria-labelledby="now-title"><h2 id="now-title">${t(s.going && s.explanation ? "touch_just_seen" : "touch_now")}</h2>${nowView(s)}</section>
    ${state.message ? html`<p class="notice ok" role="status">${state.message}</p>` : ""}
    ${s.task || !s.next_tours?.length ? "" : html`<section class="next-tours" aria-labelledby="next-title"><h2 id="next-title">${t("next_tours")}</h2>
      <ul>${nextTourLines(t, s.next_tours.slice(0, 3)).map((l) => html`<li><strong>${l.name}</strong>: ${l.line}</li>`)}</ul></section>`}
    ${s.task ? "" : html`<section aria-labelledby="tours-title"><h2 id="tours-title">${t("tours")}</h2>
      <div class="actions">${s.tours.map((tour) => tourButton(s, tour, refused))}</div>
    </section>
    <section aria-labelledby="points-title"><h2 id="points-title">${t("points")}</h2>
      <div class="actions">${s.pois.map((poi) => pointButton(poi, refused))}</div>
    </section>`}`, app);
}


/** The agent's push channel: every message, and every (re)connect, reads the screen again. */
function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(`${scheme}//${location.host}/ws`);
  let pending = false;
  ws.onopen = () => refresh();
  ws.onmessage = () => {
    // Every change: read the whole screen again (local to the robot, a few kB).
    if (pending) return;
    pending = true;
    requestAnimationFrame(async () => {
      pending = false;
      await refresh();
    });
  };
  ws.onclose = () => {
    showReachable(false);
    setTimeout(connect, 1000);
  };
}

document.addEventListener("contextmenu", (e) => e.preventDefault());
setInterval(() => {
  state.now = Date.now();
  if (state.screen?.question) draw();
}, 250);

connect();
