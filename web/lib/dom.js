// Small helpers shared by the pages: formatting and the hub connection banner.

/** "12 s", "3 min", "1 h 5 min" from seconds. */
export function duration(seconds) {
  if (seconds === null || seconds === undefined || Number.isNaN(seconds)) return "—";
  const s = Math.max(0, Math.round(seconds));
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.round(s / 60)} min`;
  return `${Math.floor(s / 3600)} h ${Math.round((s % 3600) / 60)} min`;
}

/** The browser's date and time of a Unix timestamp (seconds), on the 24-hour clock as the
 * console and the server write times ("Nov 29, 2026, 14:05"); "—" without one. A version
 * published yesterday showed its time alone, in the 12-hour clock ("12:53:58 AM"). */
export function dateTime(ts) {
  return ts ? new Date(ts * 1000).toLocaleString(undefined, { dateStyle: "medium", timeStyle: "short", hourCycle: "h23" }) : "—";
}

/** "1 safe spot", "2 safe spots": a count with its noun (English plural in -s). */
export function counted(n, noun) {
  return `${n} ${noun}${n === 1 ? "" : "s"}`;
}

export function percent(level) {
  return level === null || level === undefined ? "—" : `${Math.round(level * 100)} %`;
}

/** The value of the form control with this id (an input, a select or a textarea). */
export function inputValue(id) {
  return /** @type {HTMLInputElement} */ (document.getElementById(id)).value;
}

/**
 * A text field of a submitted form (FormData types an entry as text or a file; these forms
 * have no file inputs); null when the form has no such field.
 * @param {FormData} form
 * @param {string} name
 * @returns {string}
 */
export function formText(form, name) {
  return /** @type {string} */ (form.get(name));
}

const STATUS_TEXT = {
  connecting: "Connecting to the server…",
  open: "Connected",
  reconnecting: "Connection lost, reconnecting…",
  refused: "Disconnected",
  stopped: "Disconnected",
};

/** Keep `element` (a role=status banner) in step with the hub client's connection state. */
export function connectionBanner(hub, element) {
  const show = () => {
    element.dataset.status = hub.status;
    const reason = hub.reason ? ` (${hub.reason})` : "";
    element.textContent = `${STATUS_TEXT[hub.status] ?? hub.status}${hub.status === "open" ? "" : reason}`;
  };
  hub.addEventListener("status", show);
  show();
}
