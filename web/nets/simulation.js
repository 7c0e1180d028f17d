// The simulation: the net run at once by the server against the scripted environment of
// `guidebot petri run` (POST /api/net-editor/simulate), then stepped through here: the marking
// of the net after each of its firings, the messages it published and the replies it got.
// Or, with "Choose each reply", the net waits after each request and the user picks the reply
// (or lets time pass to its next timer); the server runs it again with the replies chosen.
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
      <div class="field"><label><input type="checkbox" name="stepwise" .checked=${ui.stepwise !== null}> Choose each reply myself</label></div>
      <button type="submit">Run simulation</button>
    </form>
    ${run && ui.stepwise ? waitingView(run.result, actions) : nothing}
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

/** What the net waits for, each a button that gives that reply; or time passing. */
function waitingView(result, actions) {
  if (result.outcome !== "waiting") return nothing;
  const waiting = result.waiting_for;
  return html`<div id="sim-waiting" role="group" aria-labelledby="sim-waiting-title"><h3 id="sim-waiting-title">The net waits (at ${result.time.toFixed(1)} s): reply</h3>
    ${waiting.length ? html`<ul class="elements">${waiting.map((w) => html`<li><button type="button" class="element" @click=${() => actions.choose({ type: w.type, payload: w.payload })}>
      ${w.type} ${Object.keys(w.payload).length ? JSON.stringify(w.payload) : ""}<span class="muted"> (${w.net}: ${w.transition})</span></button></li>`)}</ul>`
      : html`<p class="muted">No message would move it on.</p>`}
    ${result.next_timer !== null ? html`<button type="button" class="secondary" @click=${() => actions.choose({ wait: true })}>Let time pass to ${result.next_timer.toFixed(1)} s (its next timer)</button>` : nothing}
    ${!waiting.length && result.next_timer === null ? html`<p>Stuck: nothing can move it on.</p>` : nothing}</div>`;
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
