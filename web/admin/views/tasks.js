// Tasks: create, the queue (position, ETA), running tasks (progress), recent history; cancel,
// re-prioritise, reassign; a task's event history.
import { html } from "lit-html";
import { repeat } from "lit-html/directives/repeat.js";
import { confirmAction } from "/lib/confirm.js";
import { duration, inputValue } from "/lib/dom.js";
import { clock } from "/admin/venue.js";
import { atPlace, placeName, poiName, robotPlace, taskName } from "/admin/names.js";

const FINAL = new Set(["done", "failed", "cancelled"]);
const KINDS = [["tour", "Tour"], ["go_to_poi", "Point of interest"], ["go_to", "Go to node"], ["charge", "Charge"]];

/** Told to the visitor whose tour staff cancel (their panel shows the task's reason). */
export const STAFF_CANCEL_REASON = "cancelled by staff";

const describe = (ui, task) => taskName(ui.store.site, task);

/** Cancel after an accessible confirmation (tasks and robots views). */
export async function cancelTask(ui, task) {
  const label = describe(ui, task);
  const running = task.state !== "queued";
  const ok = await confirmAction({
    title: `Cancel ${label}?`,
    text: running
      ? `${task.robot ?? "Its robot"} stops and the visitor is told the tour was cancelled by staff. This cannot be undone.`
      : "It leaves the queue and its requester is told it was cancelled by staff. This cannot be undone.",
    confirm: `Cancel ${label}`,
    keep: "Keep the task",
  });
  if (!ok) return;
  await ui.act(`Cancel ${label}`, () => ui.api.post(`/api/tasks/${encodeURIComponent(task.id)}/cancel`, { reason: STAFF_CANCEL_REASON }));
}

async function create(ui, event) {
  event.preventDefault();
  const form = new FormData(event.target);
  const kind = form.get("kind");
  const target = form.get("target");
  const params = kind === "tour" ? { tour: target } : kind === "go_to_poi" ? { poi: target } : kind === "go_to" ? { node: target } : {};
  const body = { kind, params, priority: Number(form.get("priority")) };
  if (form.get("robot")) body.robot = form.get("robot");
  await ui.act(`Request ${kind}`, () => ui.api.post("/api/tasks", body));
}

function targets(ui, kind) {
  const site = ui.store.site;
  if (kind === "tour") return site.tours.map((t) => [t.id, t.name || t.id]);
  if (kind === "go_to_poi") return site.pois.map((p) => [p.id, p.name || p.id]);
  if (kind === "go_to") return site.nodes.map((n) => [n.id, `${placeName(site, n.id)} · ${n.id}`]);
  return [];
}

function createForm(ui) {
  if (!ui.operate) return "";
  const kind = ui.taskKind ?? "tour";
  const options = targets(ui, kind);
  return html`<form class="inline" @submit=${(e) => create(ui, e)} aria-label="New task">
    <label>Kind <select name="kind" @change=${(e) => { ui.taskKind = e.target.value; ui.draw(); }}>
      ${KINDS.map(([k, label]) => html`<option value=${k} ?selected=${k === kind}>${label}</option>`)}</select></label>
    ${options.length
      ? html`<label>Target <select name="target">${options.map(([id, label]) => html`<option value=${id}>${label}</option>`)}</select></label>`
      : ""}
    <label>Priority <input name="priority" type="number" min="0" max="100" value="5" size="4"></label>
    <label>Robot <select name="robot"><option value="">any</option>
      ${[...ui.store.robots.keys()].sort().map((r) => html`<option value=${r}>${r}</option>`)}</select></label>
    <button type="submit">Request task</button>
  </form>`;
}

function taskActions(ui, task) {
  const id = encodeURIComponent(task.id);
  const label = describe(ui, task);
  const reassignId = `reassign-${task.id}`;
  const priorityId = `priority-${task.id}`;
  const history = html`<button type="button" class="secondary" @click=${() => showHistory(ui, task)}>History</button>`;
  if (!ui.operate) return html`<div class="actions">${history}</div>`;
  return html`<div class="actions">
    <button type="button" class="danger" @click=${() => cancelTask(ui, task)}>Cancel <span class="sr-only">${label}</span></button>
    <label for=${priorityId} class="sr-only">Priority of ${label}</label>
    <input id=${priorityId} type="number" min="0" max="100" size="3" .value=${String(task.priority)}>
    <button type="button" class="secondary" @click=${() => ui.act(`Priority of ${label}`, () => ui.api.post(`/api/tasks/${id}/priority`, { priority: Number(inputValue(priorityId)) }))}>Set priority</button>
    <label for=${reassignId} class="sr-only">Reassign ${label} to</label>
    <select id=${reassignId}><option value="">next free robot</option>
      ${[...ui.store.robots.keys()].sort().map((r) => html`<option value=${r}>${r}</option>`)}</select>
    <button type="button" class="secondary" @click=${() => ui.act(`Reassign ${label}`, () => ui.api.post(`/api/tasks/${id}/reassign`, { robot: inputValue(reassignId) || null }))}>Reassign</button>
    ${history}
  </div>`;
}

async function showHistory(ui, task) {
  await ui.act(`History of ${describe(ui, task)}`, async () => {
    ui.history = { task, rows: await ui.api.get(`/api/tasks/${encodeURIComponent(task.id)}/history`) };
  });
}

/** Where a tour stands, from the task's own progress (what its visitor is told: the stop the
 * robot reported, skipped stops left out): "stop 2 of 3: Roman mosaics explained, going on";
 * "" for a task without stops. The Robots view says the same. */
export function tourProgress(ui, task) {
  const p = task.progress;
  if (!p?.total) return "";
  if (!p.index) return `on the way to stop 1 of ${p.total}`;
  const name = p.name ?? poiName(ui.store.site, p.poi);
  return p.stage === "explained"
    ? `stop ${p.index} of ${p.total}: ${name} explained, going on`
    : `stop ${p.index} of ${p.total}: at ${name}`;
}

/** Why a queued task has no estimated wait (its `service`, docs/visitor.md "The wait"), in the
 * words staff read; the ETA column said only "—" while the fleet was paused. */
const NO_WAIT = { paused: "fleet paused", unavailable: "no robot can take it", held_up: "held up" };

/** A queued task's estimated wait, or why there is none. */
function eta(task) {
  if (typeof task.eta_s === "number") return duration(task.eta_s);
  return NO_WAIT[task.service] ?? "—";
}

/** Where a running task stands: its tour's progress, else the robot's place. */
function progress(ui, task) {
  const tour = tourProgress(ui, task);
  if (tour) return tour;
  const s = task.robot ? ui.store.robots.get(task.robot)?.state : null;
  if (!s?.node) return "—";
  return atPlace(robotPlace(ui.store.site, s));
}

export function tasksView(ui) {
  const tasks = [...ui.store.tasks.values()];
  const queued = tasks.filter((t) => t.state === "queued").sort((a, b) => (a.queue_position ?? 1e9) - (b.queue_position ?? 1e9));
  const running = tasks.filter((t) => t.state !== "queued" && !FINAL.has(t.state));
  const history = tasks.filter((t) => FINAL.has(t.state)).sort((a, b) => b.updated_at - a.updated_at).slice(0, 50);
  const fleet = ui.store.fleet;
  return html`<h2>Tasks</h2>
    ${createForm(ui)}
    <h3>Queue</h3>
    ${fleet?.paused
      ? html`<p class="notice warn" id="queue-paused">The fleet is paused (by ${fleet.by} at ${clock(fleet.since)}${fleet.reason ? `: ${fleet.reason}` : ""}): no queued task starts until someone resumes it in the Fleet view.</p>`
      : ""}
    <table aria-label="Queued tasks">
      <thead><tr><th scope="col">#</th><th scope="col">Task</th><th scope="col">Priority</th><th scope="col">Robot</th><th scope="col">ETA</th><th scope="col">Requested by</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${repeat(queued, (t) => t.id, (t) => html`<tr data-task=${t.id}><td>${t.queue_position ?? "—"}</td><td>${describe(ui, t)}</td><td>${t.priority}</td><td>${t.pinned_robot ?? "any"}</td><td>${eta(t)}</td><td>${t.requester}</td><td>${taskActions(ui, t)}</td></tr>`)}</tbody>
    </table>
    ${queued.length ? "" : html`<p class="muted">The queue is empty.</p>`}
    <h3>Running</h3>
    <table aria-label="Running tasks">
      <thead><tr><th scope="col">Task</th><th scope="col">Robot</th><th scope="col">State</th><th scope="col">Progress</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${repeat(running, (t) => t.id, (t) => html`<tr data-task=${t.id}><td>${describe(ui, t)}${t.internal ? html` <span class="muted">(automatic)</span>` : ""}</td><td>${t.robot ?? "—"}</td><td>${t.state}</td><td>${progress(ui, t)}</td><td>${taskActions(ui, t)}</td></tr>`)}</tbody>
    </table>
    <h3>History</h3>
    <table aria-label="Finished tasks">
      <thead><tr><th scope="col">Task</th><th scope="col">Robot</th><th scope="col">Outcome</th><th scope="col">Ended</th><th scope="col">Reason</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${repeat(history, (t) => t.id, (t) => html`<tr data-task=${t.id}><td>${describe(ui, t)}</td><td>${t.robot ?? "—"}</td><td class=${`state-${t.state}`}>${t.state}</td><td>${clock(t.ended_at ?? t.updated_at)}</td><td>${t.reason ?? ""}</td><td><button type="button" class="secondary" @click=${() => showHistory(ui, t)}>History <span class="sr-only">of ${describe(ui, t)}</span></button></td></tr>`)}</tbody>
    </table>
    ${ui.history
      ? html`<section aria-labelledby="history-title"><h3 id="history-title">History of ${describe(ui, ui.history.task)} <span class="muted">(task ${ui.history.task.id})</span></h3>
          <ol>${ui.history.rows.map((r) => html`<li>${clock(r.at)} ${r.event}: ${r.state}${r.robot ? ` (${r.robot})` : ""}${r.reason ? ` — ${r.reason}` : ""}</li>`)}</ol></section>`
      : ""}`;
}
