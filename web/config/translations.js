// The site editor's translations view: per language, the texts that are missing or older than
// their source; a translator edits them beside the source, or sends a PO or XLIFF file to an
// agency and imports it back. The server keeps the rules (backend/site/translations.py): this
// page shows its answers and writes through /api/site/draft/translations.
import { html, nothing, render } from "lit-html";
import { counted } from "/lib/dom.js";

const BASE = "/api/site/draft/translations";
const STATES = {
  missing: "✗ Missing",
  stale: "⚠ Older than its source",
  current: "✓ Current",
};
const FILTERS = [["todo", "Missing or older"], ["all", "All texts"]];

/** The language's own name in English, when the browser knows it ("de" → "German"). */
function languageName(lang) {
  try {
    return new Intl.DisplayNames(["en"], { type: "language" }).of(lang) ?? lang;
  } catch {
    return lang;
  }
}

const LANG_TAG = /^[a-z]{2,3}(-[A-Za-z0-9]{2,8})?$/;

/**
 * What a publish of the draft leaves untranslated, as a sentence ("" when nothing): publishing
 * is not blocked by it, but the installer is told.
 */
export async function translationWarning(api, model) {
  await model.saving;
  const o = await api.get(BASE).catch(() => null);
  const gaps = (o?.languages ?? []).filter((l) => l.missing || l.stale);
  if (!gaps.length) return "";
  const each = gaps.map((l) => `${languageName(l.lang)} ${l.missing} missing, ${l.stale} older than their source`);
  return ` Not yet translated: ${each.join("; ")}; visitors get ${languageName(o.source_language)} for them (see Translations).`;
}

/**
 * Mount the view: a switch between the plan and the translations in `nav`, the view in `root`,
 * `columns` (the plan editor) hidden while it shows.
 * @param {{model: any, api: any, sendFile: Function, root: HTMLElement, nav: HTMLElement, columns: HTMLElement}} ctx
 */
export function mountTranslations({ model, api, sendFile, root, nav, columns }) {
  const ui = {
    open: false, overview: null, lang: null, texts: null, filter: "todo", notice: null,
    report: null, busy: Promise.resolve(),
  };

  const say = (text, error = false) => { ui.notice = { text, error }; draw(); };

  async function refresh() {
    if (!ui.open) return;
    await model.saving;
    try {
      ui.overview = await api.get(BASE);
      const langs = ui.overview.languages.map((l) => l.lang);
      if (!langs.includes(ui.lang)) ui.lang = langs[0] ?? null;
      ui.texts = ui.lang ? await api.get(`${BASE}/${encodeURIComponent(ui.lang)}`) : null;
    } catch (err) {
      say(err.message, true);
    }
    draw();
  }
  // One refresh at a time, in order: a later change is shown after an earlier one.
  const update = () => { ui.busy = ui.busy.then(refresh); return ui.busy; };
  model.addEventListener("change", update);

  function show(open) {
    ui.open = open;
    columns.hidden = open;
    root.hidden = !open;
    draw();
    if (open) update();
  }

  async function write(entry, text) {
    await model.saving;
    try {
      const reply = await api.put(`${BASE}/${encodeURIComponent(ui.lang)}`, {
        revision: model.revision, texts: [{ key: entry.key, text }],
      });
      await model.load();
      const verb = text ? (entry.translation === text ? "marked current" : "saved") : "removed";
      say(`${entry.label} in ${ui.lang}: ${verb} (draft revision ${reply.revision}).`);
    } catch (err) {
      say(err.message, true);
    }
  }

  function addLanguage(event) {
    event.preventDefault();
    const input = event.target.elements.lang;
    const lang = input.value.trim();
    const doc = model.doc;
    if (!LANG_TAG.test(lang)) return say(`${lang || "(empty)"} is not a language tag such as fr or pt-BR.`, true);
    if (lang === (doc.default_language || "en") || (doc.languages ?? []).includes(lang)) return say(`${lang} is already a language of the site.`, true);
    ui.lang = lang;
    ui.report = null;
    model.edit(`add language ${lang}`, (d) => { d.languages = [...(d.languages ?? []), lang]; });
    input.value = "";
    say(`${languageName(lang)} (${lang}) added: its texts are all missing until translated.`);
  }

  async function exportFile(format) {
    await model.saving;
    try {
      const blob = await api.get(`${BASE}/${encodeURIComponent(ui.lang)}/export?format=${format}`);
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = `site-${ui.lang}.${format === "po" ? "po" : "xlf"}`;
      a.click();
      say(`${a.download} exported: ${counted(ui.texts.texts.length, "text")}, the ones older than their source marked fuzzy.`);
    } catch (err) {
      say(`Export refused: ${err.message}`, true);
    }
  }

  async function importFile(input) {
    const file = input.files?.[0];
    if (!file) return;
    const format = /\.po$/i.test(file.name) ? "po" : /\.(xlf|xliff)$/i.test(file.name) ? "xliff" : null;
    input.value = "";
    if (!format) return say(`${file.name} refused: a translation file ends in .po, .xlf or .xliff.`, true);
    await model.saving;
    try {
      const url = `${BASE}/${encodeURIComponent(ui.lang)}/import?revision=${model.revision}&format=${format}`;
      const type = format === "po" ? "text/x-gettext-translation" : "application/x-xliff+xml";
      ui.report = { file: file.name, ...(await sendFile("POST", url, await file.arrayBuffer(), type)) };
      await model.load();
      const r = ui.report;
      say(`${file.name} imported: ${counted(r.changed.length, "text")} changed, ${r.unchanged} unchanged, ${r.skipped.length} not imported.`);
    } catch (err) {
      ui.report = null;
      say(`${file.name} refused, nothing was changed: ${err.message}`, true);
    }
  }

  function row(entry) {
    const id = `tr-${entry.key.replaceAll(/[^A-Za-z0-9]/g, "-")}`;
    return html`<tr data-key=${entry.key} class=${`tr-${entry.state}`}>
      <th scope="row" id=${`${id}-label`}>${entry.label}</th>
      <td lang=${entry.source_lang} class="source">${entry.source}</td>
      <td><textarea id=${id} lang=${ui.lang} rows="2" aria-labelledby=${`${id}-label ${id}-lang`}
        .value=${entry.translation} @change=${(e) => write(entry, e.target.value.trim())}></textarea>
        <span id=${`${id}-lang`} class="sr-only">in ${languageName(ui.lang)}</span></td>
      <td class="state">${STATES[entry.state]}${entry.state === "stale" ? html`<br><button type="button" class="secondary small"
        aria-label=${`Keep the ${languageName(ui.lang)} translation of ${entry.label}: it is still right`}
        @click=${() => write(entry, entry.translation)}>Still right</button>` : nothing}</td></tr>`;
  }

  function draw() {
    render(html`<button type="button" class=${ui.open ? "secondary" : "current"} aria-pressed=${ui.open ? "false" : "true"}
        @click=${() => show(false)}>Plan and elements</button>
      <button type="button" id="translations-switch" class=${ui.open ? "current" : "secondary"} aria-pressed=${ui.open ? "true" : "false"}
        @click=${() => show(true)}>Translations</button>`, nav);
    if (!ui.open) return render(nothing, root);
    const o = ui.overview;
    const source = o ? `${languageName(o.source_language)} (${o.source_language})` : "";
    const texts = ui.texts?.texts ?? [];
    const shown = ui.filter === "all" ? texts : texts.filter((t) => t.state !== "current");
    const name = ui.lang ? `${languageName(ui.lang)} (${ui.lang})` : "";
    render(html`
      <h2 id="translations-title">Translations</h2>
      ${ui.notice ? html`<div class=${`notice ${ui.notice.error ? "error" : "ok"}`} role=${ui.notice.error ? "alert" : "status"}>${ui.notice.text}</div>` : nothing}
      ${!o ? html`<p class="muted">Loading…</p>` : html`
      <p>The source of every text is the site's default language, ${source}. Missing texts and texts older than
        their source do not stop publishing: visitors get the source text, marked "Not yet translated".</p>
      <table class="languages"><caption>Texts per language</caption>
        <thead><tr><th scope="col">Language</th><th scope="col">Missing</th><th scope="col">Older than source</th><th scope="col">Current</th><th scope="col"><span class="sr-only">Action</span></th></tr></thead>
        <tbody>${o.languages.map((l) => html`<tr data-lang=${l.lang}><th scope="row">${languageName(l.lang)} (${l.lang})</th>
          <td>${l.missing}</td><td>${l.stale}</td><td>${l.current} of ${l.total}</td>
          <td><button type="button" class="secondary small" aria-pressed=${l.lang === ui.lang ? "true" : "false"}
            @click=${() => { ui.lang = l.lang; ui.report = null; update(); }}>${l.lang === ui.lang ? "✓ " : ""}Translate ${languageName(l.lang)}</button></td></tr>`)}
        </tbody></table>
      <form class="add-language" @submit=${addLanguage}>
        <label>Add a language (tag, e.g. fr) <input name="lang" maxlength="16" autocomplete="off"></label>
        <button type="submit" class="secondary">Add language</button></form>
      ${ui.lang ? html`
      <h3 id="texts-title">${name}</h3>
      <div class="translation-files">
        <button type="button" class="secondary" @click=${() => exportFile("po")}>Export ${ui.lang} as PO</button>
        <button type="button" class="secondary" @click=${() => exportFile("xliff")}>Export ${ui.lang} as XLIFF</button>
        <label>Import a translated PO or XLIFF file <input type="file" accept=".po,.xlf,.xliff" @change=${(e) => importFile(e.target)}></label>
      </div>
      ${ui.report ? html`<section class="import-report" aria-labelledby="report-title"><h4 id="report-title">What ${ui.report.file} changed</h4>
        ${ui.report.changed.length ? html`<ul aria-label="Changed texts">${ui.report.changed.map((c) => html`<li>${c.label}:
          <span lang=${ui.lang}>${c.before || "(missing)"}</span> → <span lang=${ui.lang}>${c.after}</span>${c.stale ? " (translated from an older source text: marked older than its source)" : ""}</li>`)}</ul>`
          : html`<p>No text changed.</p>`}
        ${ui.report.skipped.length ? html`<ul aria-label="Texts not imported">${ui.report.skipped.map((s) => html`<li>${s.key}: ${s.reason}</li>`)}</ul>` : nothing}</section>` : nothing}
      <fieldset class="filter"><legend>Show</legend>${FILTERS.map(([value, label]) => html`
        <label><input type="radio" name="tr-filter" value=${value} .checked=${ui.filter === value}
          @change=${() => { ui.filter = value; draw(); }}> ${label}</label>`)}</fieldset>
      ${shown.length ? html`<table class="side-by-side" aria-labelledby="texts-title">
        <thead><tr><th scope="col">Text</th><th scope="col">Source: ${source}</th><th scope="col">Translation: ${name}</th><th scope="col">State</th></tr></thead>
        <tbody>${shown.map(row)}</tbody></table>`
        : html`<p class="ok-text">Every text is translated from its current source.</p>`}` : html`<p class="muted">No language besides the source yet: add one above.</p>`}`}`, root);
  }

  draw();
}
