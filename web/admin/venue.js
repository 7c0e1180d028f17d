// The venue's time zone (GUIDEBOT_TIMEZONE, named by GET /api/site/map): every time the console
// shows or reads is the venue's, whatever the browser's zone, since staff may sign in from
// elsewhere (a regional office, on call at home abroad); the header says which zone it is
// (docs/console.md, "Time"). Bookings were in the venue's zone and everything else in the
// browser's: the same moment read two ways on one page.

let zone = "UTC";

/**
 * Take the venue's zone (at sign-in, with the site). A name the browser does not know falls
 * back to UTC, which the header then names.
 * @param {string | null | undefined} name an IANA zone name
 */
export function setVenueZone(name) {
  try {
    new Intl.DateTimeFormat("en", { timeZone: name || "UTC" });
    zone = name || "UTC";
  } catch {
    zone = "UTC";
  }
}

/** The venue's zone's name ("Europe/Madrid"). */
export function venueZone() {
  return zone;
}

/** The venue's clock time of a Unix timestamp (seconds), on the 24-hour clock as the server
 * writes times (bookings, "by 14:00" in an alert): "16:52:10"; "—" without one. */
export function clock(ts) {
  return ts ? new Date(ts * 1000).toLocaleTimeString(undefined, { timeZone: zone, hourCycle: "h23" }) : "—";
}

/** The venue's date and time of a Unix timestamp (seconds), "—" without one. */
export function dateTime(ts) {
  return ts ? new Date(ts * 1000).toLocaleString(undefined, { timeZone: zone, hourCycle: "h23" }) : "—";
}

/** The venue's hours and minutes now ("14:02"), for the header. */
export function venueNow() {
  return new Date().toLocaleTimeString(undefined, { timeZone: zone, hourCycle: "h23", hour: "2-digit", minute: "2-digit" });
}

/** The venue's date (YYYY-MM-DD) at `date` (default now): "today" at the venue. */
export function venueDay(date = new Date()) {
  const parts = wall(date.getTime());
  return `${parts.year}-${pad(parts.month)}-${pad(parts.day)}`;
}

/**
 * Unix seconds of a wall-clock time at the venue ("2026-11-28T14:00", a datetime-local field's
 * value); null for an empty value. A time a daylight-saving change skips or repeats is read
 * with the offset before the change.
 * @param {string} local
 * @returns {number | null}
 */
export function venueSeconds(local) {
  const m = /^(\d{4})-(\d{2})-(\d{2})T(\d{2}):(\d{2})(?::(\d{2}))?/.exec(local ?? "");
  if (!m) return null;
  const asUtc = Date.UTC(+m[1], +m[2] - 1, +m[3], +m[4], +m[5], +(m[6] ?? 0));
  let at = asUtc - offset(asUtc);
  at = asUtc - offset(at); // the offset at the moment itself (across a change)
  return at / 1000;
}

const pad = (n) => String(n).padStart(2, "0");

/** The venue's calendar fields at a moment (ms). */
function wall(ms) {
  const format = new Intl.DateTimeFormat("en-US", {
    timeZone: zone, hourCycle: "h23", year: "numeric", month: "numeric", day: "numeric",
    hour: "numeric", minute: "numeric", second: "numeric",
  });
  /** @type {Record<string, number>} */
  const out = {};
  for (const p of format.formatToParts(new Date(ms))) if (p.type !== "literal") out[p.type] = Number(p.value);
  return out;
}

/** The venue's offset from UTC (ms) at a moment (ms). */
function offset(ms) {
  const p = wall(ms);
  const whole = Math.floor(ms / 1000) * 1000;
  return Date.UTC(p.year, p.month - 1, p.day, p.hour, p.minute, p.second) - whole;
}
