// Bookings: staff book a tour (or one point's visit) for a date and time in the venue's time
// zone, once or recurring, move and cancel it, and read its history; occurrences that cannot be
// served are flagged with the reason (docs/console.md, "Bookings"; docs/server.md, "Bookings").
import { html } from "lit-html";
import { formText } from "/lib/dom.js";
import { dateTime, venueDay } from "/admin/venue.js";

const DAYS = [["mon", "Mon"], ["tue", "Tue"], ["wed", "Wed"], ["thu", "Thu"], ["fri", "Fri"], ["sat", "Sat"], ["sun", "Sun"]];
const EVERY = { once: "once", daily: "every day", weekly: "every week" };

const isoDay = (date) => new Date(date.getTime() - date.getTimezoneOffset() * 60000).toISOString().slice(0, 10);

/** How old the day's listing may get while the view is shown: a robot reserved, a booking
 * started or missed, one made on another screen come with no message of their own (the view
 * loaded once, at its first opening, and said "booked" long after the tour started). */
const REFRESH_MS = 10000;

function state(ui) {
  if (!ui.bookings) {
    ui.bookings = { day: venueDay(), data: null, error: null, every: "once", moving: null, history: null, loadedAt: 0, loading: 0 };
  }
  const b = ui.bookings;
  if (!b.loading && Date.now() - b.loadedAt > REFRESH_MS) load(ui); // drawn: shown now
  return b;
}

/** Read the chosen day's bookings; an answer for a day no longer chosen is dropped. */
async function load(ui) {
  const b = ui.bookings;
  const day = b.day;
  const asked = (b.loading = (b.asked = (b.asked ?? 0) + 1));
  try {
    const data = await ui.api.get(`/api/bookings?start=${encodeURIComponent(day)}`);
    if (day === b.day) {
      b.data = data;
      b.error = null;
    }
  } catch (err) {
    b.error = err.message;
  } finally {
    if (b.loading === asked) b.loading = 0;
    b.loadedAt = Date.now();
  }
  ui.draw();
}

function shiftDay(ui, days) {
  const d = new Date(`${ui.bookings.day}T12:00`);
  d.setDate(d.getDate() + days);
  ui.bookings.day = isoDay(d);
  load(ui);
}

function languages(site) {
  return [site.default_language, ...site.languages.filter((l) => l !== site.default_language)];
}

const when = (o) => o.local.slice(11, 16);

function repeats(o) {
  const r = o.recurrence;
  if (r.every === "once") return "once";
  const days = r.every === "weekly" && r.days.length ? ` (${r.days.join(", ")})` : "";
  const until = r.until ? ` until ${r.until}` : "";
  return `${EVERY[r.every]}${days}${until}`;
}

function stateOf(o) {
  if (o.status === "cancelled") return "cancelled";
  if (o.outcome === "started") return `started (task ${o.task_id})`;
  if (o.outcome === "missed") return `missed: ${o.missed_reason}`;
  return o.robot ? `booked, ${o.robot} reserved` : "booked";
}

function bookForm(ui, b) {
  const site = ui.store.site;
  const submit = (event) => {
    event.preventDefault();
    const form = new FormData(event.target);
    const [kind, target] = formText(form, "what").split(":");
    const recurrence = { every: form.get("every") };
    if (recurrence.every === "weekly") recurrence.days = form.getAll("days");
    if (recurrence.every !== "once") {
      if (form.get("until")) recurrence.until = form.get("until");
      recurrence.except_dates = formText(form, "except").split(/[\s,]+/).filter(Boolean);
    }
    const body = {
      [kind]: target,
      start: form.get("start"),
      lang: form.get("lang"),
      group_size: Number(form.get("group_size")),
      note: formText(form, "note").trim(),
      public: form.get("public") === "on",
      recurrence,
    };
    if (form.get("meeting_point")) body.meeting_point = form.get("meeting_point");
    ui.act("Book", async () => {
      const made = await ui.api.post("/api/bookings", body);
      event.target.reset();
      b.every = "once";
      b.day = made.start.slice(0, 10);
      await load(ui);
    });
  };
  return html`<form class="book-form" @submit=${submit} aria-labelledby="book-title">
    <h3 id="book-title">Book</h3>
    <label>Tour or visit <select name="what" required>
      ${site.tours.map((t) => html`<option value=${`tour:${t.id}`}>${t.name || t.id}</option>`)}
      ${site.pois.map((p) => html`<option value=${`poi:${p.id}`}>Visit: ${p.name || p.id}</option>`)}
    </select></label>
    <label>Date and time <input name="start" type="datetime-local" required value=${`${b.day}T14:00`}></label>
    <label>Language <select name="lang">${languages(site).map((l) => html`<option value=${l}>${l}</option>`)}</select></label>
    <label>Group size <input name="group_size" type="number" min="1" max="500" required value="10"></label>
    <label>Meeting point <select name="meeting_point">
      <option value="">The first stop</option>
      ${site.pois.map((p) => html`<option value=${p.id}>${p.name || p.id}</option>`)}
    </select></label>
    <label>Note <input name="note" maxlength="500"></label>
    <label><input name="public" type="checkbox" checked> Shown to visitors as a next tour</label>
    <label>Repeats <select name="every" @change=${(e) => { b.every = e.target.value; ui.draw(); }}>
      ${Object.entries(EVERY).map(([value, label]) => html`<option value=${value} ?selected=${b.every === value}>${label}</option>`)}
    </select></label>
    ${b.every === "weekly"
      ? html`<fieldset><legend>On</legend>${DAYS.map(([value, label]) => html`<label><input type="checkbox" name="days" value=${value}> ${label}</label>`)}</fieldset>`
      : ""}
    ${b.every !== "once"
      ? html`<label>Until <input name="until" type="date"></label>
        <label>Except (closed days) <input name="except" placeholder="2026-12-25, 2027-01-01"></label>`
      : ""}
    <button type="submit">Book it</button>
  </form>`;
}

function moveForm(ui, b, o) {
  const site = ui.store.site;
  const submit = (event) => {
    event.preventDefault();
    const form = new FormData(event.target);
    const body = { start: form.get("start"), group_size: Number(form.get("group_size")) };
    if (form.get("meeting_point") !== o.meeting_point) body.meeting_point = form.get("meeting_point");
    ui.act(`Move ${o.name}`, async () => {
      await ui.api.post(`/api/bookings/${encodeURIComponent(o.id)}/move`, body);
      b.moving = null;
      b.day = body.start.slice(0, 10);
      await load(ui);
    });
  };
  return html`<form class="move-form" @submit=${submit} aria-labelledby="move-title">
    <h3 id="move-title">Move ${o.name} (${o.local})</h3>
    ${o.recurrence.every !== "once" ? html`<p class="muted">A series moves as a whole: every coming date.</p>` : ""}
    <label>New date and time <input name="start" type="datetime-local" required value=${o.start}></label>
    <label>Group size <input name="group_size" type="number" min="1" max="500" required value=${o.group_size}></label>
    <label>Meeting point <select name="meeting_point">
      ${site.pois.map((p) => html`<option value=${p.id} ?selected=${p.id === o.meeting_point}>${p.name || p.id}</option>`)}
    </select></label>
    <button type="submit">Move it</button>
    <button type="button" class="secondary" @click=${() => { b.moving = null; ui.draw(); }}>Keep it</button>
  </form>`;
}

function historyView(b) {
  const h = b.history;
  if (!h) return "";
  const detail = (d) => Object.entries(d).map(([k, v]) => `${k}: ${typeof v === "object" && v ? `${v.from} → ${v.to}` : v}`).join("; ");
  return html`<section aria-labelledby="history-title">
    <h3 id="history-title">History of ${h.name}</h3>
    <table aria-label="Booking history">
      <thead><tr><th scope="col">When</th><th scope="col">What</th><th scope="col">By</th><th scope="col">Detail</th></tr></thead>
      <tbody>${h.rows.map((r) => html`<tr>
        <td>${dateTime(r.at)}</td><td>${r.action}</td><td>${r.by}</td><td>${detail(r.detail)}</td>
      </tr>`)}</tbody>
    </table>
  </section>`;
}

export function bookingsView(ui) {
  const b = state(ui);
  const occurrences = b.data?.occurrences ?? [];
  const flags = b.data?.flags ?? [];
  const cancel = (o, occurrence) => ui.act(occurrence ? `Cancel ${o.name} on ${occurrence}` : `Cancel ${o.name}`, async () => {
    await ui.api.post(`/api/bookings/${encodeURIComponent(o.id)}/cancel`, occurrence ? { occurrence } : {});
    await load(ui);
  });
  const history = async (o) => {
    try {
      b.history = { name: `${o.name} (${o.id})`, rows: await ui.api.get(`/api/bookings/${encodeURIComponent(o.id)}/history`) };
    } catch (err) {
      b.error = err.message;
    }
    ui.draw();
  };
  return html`<h2>Bookings</h2>
    <p class="muted">A robot is reserved a few minutes ahead (long enough to end a tour and get there) and sent to the meeting point; staff are told if it cannot be there in time; the tour starts at its time, ahead of walk-ups. Times are the venue's (${b.data?.tz ?? "…"}).</p>
    ${b.error ? html`<p class="notice error" role="alert">Bookings could not be read: ${b.error}</p>` : ""}
    ${flags.length
      ? html`<div class="notice error" role="alert"><strong>Cannot be served as things stand:</strong>
          <ul>${flags.map((f) => html`<li>${f.local.replace("T", " ")} (booking ${f.booking}): ${f.reason}</li>`)}</ul></div>`
      : ""}
    <div class="day-picker">
      <button type="button" class="secondary" @click=${() => shiftDay(ui, -1)}>Previous day</button>
      <label>Day <input type="date" .value=${b.day} @change=${(e) => { b.day = e.target.value; load(ui); }}></label>
      <button type="button" class="secondary" @click=${() => shiftDay(ui, 1)}>Next day</button>
      <button type="button" class="secondary" @click=${() => load(ui)}>Refresh</button>
    </div>
    <table aria-label=${`Bookings on ${b.day}`}>
      <thead><tr><th scope="col">Time</th><th scope="col">Tour</th><th scope="col">Language</th><th scope="col">Group</th>
        <th scope="col">Meet at</th><th scope="col">Repeats</th><th scope="col">State</th><th scope="col">Note</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>
        ${occurrences.length ? "" : html`<tr><td colspan="9">Nothing booked on ${b.day}.</td></tr>`}
        ${occurrences.map((o) => html`<tr class=${o.flag ? "flagged" : ""}>
          <td>${when(o)}</td>
          <td>${o.name}${o.public ? "" : html` <span class="badge">private</span>`}</td>
          <td>${o.lang}</td>
          <td>${o.group_size}</td>
          <td>${o.meeting_point_name}</td>
          <td>${repeats(o)}</td>
          <td>${stateOf(o)}${o.flag ? html` <span class="badge bad">cannot be served: ${o.flag}</span>` : ""}</td>
          <td>${o.note}</td>
          <td>
            <button type="button" class="secondary" @click=${() => history(o)}>History of ${o.name} at ${when(o)}</button>
            ${ui.operate && o.status === "booked" && !o.outcome
              ? html`<button type="button" class="secondary" @click=${() => { b.moving = o; ui.draw(); }}>Move ${o.name} at ${when(o)}</button>
                ${o.recurrence.every !== "once"
                  ? html`<button type="button" class="secondary" @click=${() => cancel(o, o.local.slice(0, 10))}>Cancel ${o.name} on ${o.local.slice(0, 10)} only</button>`
                  : ""}
                <button type="button" class="secondary" @click=${() => cancel(o, null)}>Cancel ${o.name} at ${when(o)}</button>`
              : ""}
          </td>
        </tr>`)}
      </tbody>
    </table>
    ${b.moving && ui.operate ? moveForm(ui, b, b.moving) : ""}
    ${historyView(b)}
    ${ui.operate ? bookForm(ui, b) : ""}`;
}
