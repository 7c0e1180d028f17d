// Texts of the visitor pages (panel and robot touch screen) from one JSON file per language in
// /lang/<tag>.json (docs/visitor.md, "Adding a language"). A key missing from a language falls
// back to English, then to the key itself, so a half-translated file never breaks a page.

const FALLBACK = "en";
const cache = new Map();

async function load(tag) {
  if (!cache.has(tag)) {
    cache.set(
      tag,
      fetch(`/lang/${encodeURIComponent(tag)}.json`)
        .then((r) => (r.ok ? r.json() : {}))
        .catch(() => ({})),
    );
  }
  return cache.get(tag);
}

/** The language file's tag for a BCP 47 tag: itself if shipped, else its base ("es-MX" -> "es"). */
function candidates(tag) {
  const base = tag.split("-")[0];
  return base === tag ? [tag] : [tag, base];
}

export class Texts {
  /** @param {string} lang @param {Record<string,string>} own @param {Record<string,string>} fallback */
  constructor(lang, own, fallback) {
    this.lang = lang;
    this.own = own;
    this.fallback = fallback;
  }

  /** The text of `key` with `{name}` placeholders filled from `vars` (as plain text). */
  t(key, vars = {}) {
    const template = this.own[key] ?? this.fallback[key] ?? key;
    return template.replace(/\{(\w+)\}/g, (whole, name) => (name in vars ? String(vars[name]) : whole));
  }

  /** "about 4 min" style durations in this language ("30 s", "4 min", "1 h 5 min"). */
  duration(seconds) {
    if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return "—";
    const s = Math.max(0, Math.round(seconds));
    if (s < 60) return `${s} s`;
    if (s < 3600) return `${Math.max(1, Math.round(s / 60))} min`;
    return `${Math.floor(s / 3600)} h ${Math.round((s % 3600) / 60)} min`;
  }

  /** Name of the language in itself ("Español"), for the language picker. */
  get name() {
    return this.own.language_name ?? this.lang;
  }
}

/** Load the texts of `lang` (with English behind them). */
export async function loadTexts(lang) {
  const fallback = await load(FALLBACK);
  for (const tag of candidates(lang)) {
    const own = await load(tag);
    if (Object.keys(own).length) return new Texts(lang, own, fallback);
  }
  return new Texts(lang, fallback, fallback);
}

/** The visitor's preferred language among `offered` (the browser's list), else `fallback`. */
export function preferredLanguage(offered, fallback) {
  for (const wanted of navigator.languages ?? [navigator.language]) {
    for (const tag of candidates(String(wanted).toLowerCase())) {
      const hit = offered.find((o) => o.toLowerCase() === tag);
      if (hit) return hit;
    }
  }
  return fallback;
}
