// The simulation: the net run at once by the server against the scripted environment of
// `guidebot petri run` (POST /api/net-editor/simulate), then stepped through here: the marking
// of the net after each of its firings, the messages it published and the replies it got.
import { html, nothing } from "lit-html";

/** Steps of a run: each firing (or the end) of the simulated net itself. */
export class Run {
  constructor(result) {
    this.result = result;
    this.top = `${result.net}#run`;
    this.steps = [];
    result.trace.forEach((m, i) => {
      if (m.type === "petri_net_event" && m.payload.instance_id === this.top) this.steps.push(i);
    });
    this.at = 0; // index in steps: 0 is the start
  }

  get done() {
    return this.at >= this.steps.length - 1;
  }

  /** The messages up to the current step. */
  seen() {
    return this.result.trace.slice(0, (this.steps[this.at] ?? -1) + 1);
  }

  /** The net's marking after the current step. */
  marking() {
    const out = new Map();
    for (const m of this.seen()) {
      if (m.type !== "petri_net_event" || m.payload.instance_id !== this.top) continue;
      if (m.payload.kind !== "fired") out.clear();
      for (const [place, n] of Object.entries(m.payload.marking)) out.set(place, n);
    }
    return out;
  }

  /** The transition(s) the current step fired. */
  fired() {
    const m = this.result.trace[this.steps[this.at]];
    return m?.payload.kind === "fired" ? m.payload.transitions ?? [m.payload.transition] : [];
  }

  time() {
    return this.result.trace[this.steps[this.at]]?.payload.time ?? 0;
  }

  /** The trace as JSON lines (what `guidebot petri run --trace` writes). */
  traceFile() {
    return this.result.trace.map((m) => JSON.stringify(m)).join("\n") + "\n";
  }
}

/** Parameters with their defaults, as the starting text of the form. */
export function defaultParams(doc) {
  const out = {};
  for (const p of doc.params) out[p.name] = p.required ? null : p.default;
  return JSON.stringify(out, null, 1);
}

/** The panel: parameters, replies, run, step, and what happened. */
export function simulationPanel(ui, actions) {
  const run = ui.run;
  const messages = run ? run.seen().filter((m) => !m.type.startsWith("petri_net_")) : [];
  return html`<section aria-labelledby="sim-title"><h2 id="sim-title">Simulate</h2>
    <form class="form" @submit=${(e) => { e.preventDefault(); actions.start(new FormData(e.target)); }}>
      <div class="field"><label for="sim-params">Parameters (JSON object)</label>
        <textarea id="sim-params" name="params" rows="3" .value=${ui.simParams}></textarea></div>
      <div class="field"><label for="sim-replies">Replies instead of the defaults (one TYPE=JSON a line; [] never answers)</label>
        <textarea id="sim-replies" name="replies" rows="2" .value=${ui.simReplies}></textarea></div>
      <button type="submit">Run simulation</button>
    </form>
    ${run ? html`
      <p id="sim-status" role="status">Step ${run.at} of ${run.steps.length - 1} · ${run.time().toFixed(1)} s
        ${run.fired().length ? html` · fired ${run.fired().join(", ")}` : nothing}
        ${run.done ? html` · <strong>outcome ${run.result.outcome}</strong>` : nothing}</p>
      <div class="bar">
        <button type="button" class="secondary" ?disabled=${run.at === 0} @click=${actions.reset}>Reset</button>
        <button type="button" ?disabled=${run.done} @click=${actions.step}>Step</button>
        ${ui.playing ? html`<button type="button" @click=${actions.pause}>Pause</button>`
          : html`<button type="button" ?disabled=${run.done} @click=${actions.play}>Run</button>`}
        <button type="button" class="secondary" ?disabled=${run.done} @click=${actions.end}>To the end</button>
        <button type="button" class="secondary" @click=${actions.download}>Download trace</button>
        <button type="button" class="secondary" @click=${actions.close}>Stop simulating</button>
      </div>
      <h3>Messages (${messages.length})</h3>
      <ol class="sim-log" aria-label="Messages of the simulation">${messages.slice(-50).map((m) => html`<li>
        ${m.source === "dispatch" ? "published" : "reply"} <code>${m.type}</code> ${JSON.stringify(m.payload)}</li>`)}</ol>` : nothing}
  </section>`;
}

/** `TYPE=JSON` lines to the replies object (the --reply option of `guidebot petri run`). */
export function parseReplies(text) {
  const out = {};
  for (const line of text.split("\n").map((l) => l.trim()).filter(Boolean)) {
    const at = line.indexOf("=");
    if (at < 1) throw new Error(`"${line}": expected TYPE=JSON`);
    let value;
    try {
      value = JSON.parse(line.slice(at + 1));
    } catch {
      throw new Error(`"${line}": the reply is not JSON`);
    }
    out[line.slice(0, at)] = Array.isArray(value) ? value : [value];
  }
  return out;
}
