// Robots: connection, battery, pose, task and tour step, nets, RoboCAN modules, last errors;
// actions: charge, send to a node, out of service and back, pause a VDA 5050 vehicle and let it
// go on, cancel the task.
import { html } from "lit-html";
import { inputValue, percent } from "/lib/dom.js";
import { clock } from "/admin/venue.js";
import { evacuationText, floorName, linkState, placeName, robotPlace, robotTaskId, taskLabel, waitingFor } from "/admin/names.js";
import { cancelTask, tourProgress } from "/admin/views/tasks.js";

/** The robot's task and where its tour stands, as the Tasks view says it ("Tour: Highlights,
 * stop 2 of 3: Bronze Age sword explained, going on"): not "at Bronze Age sword (2/3)" from
 * the last point the robot showed, which it said all the way to the next stop. */
function taskText(ui, robot) {
  const id = robotTaskId(robot);
  const task = id ? ui.store.tasks.get(id) : null;
  const step = task ? tourProgress(ui, task) : "";
  return `${taskLabel(ui.store, id)}${step ? `, ${step}` : ""}`;
}

function actions(ui, robot) {
  if (!ui.operate) return "";
  const name = robot.name;
  const out = Boolean(robot.info?.out_of_service);
  const taskId = robotTaskId(robot);
  const send = (kind, params) => ui.act(`${kind} ${name}`, () => ui.api.post("/api/tasks", { kind, params, robot: name, priority: 10 }));
  const nodeSelect = `node-${name}`;
  const vda = ui.store.site.robots.find((r) => r.name === name)?.interface === "vda5050";
  const paused = robot.state?.navigation === "paused";
  const pause = paused ? `Let ${name} go on` : `Pause ${name}`;
  return html`<div class="actions">
    <button type="button" @click=${() => ui.act(`charge ${name}`, () => ui.api.post(`/api/robots/${encodeURIComponent(name)}/charge`, {}))}>Send ${name} to charge</button>
    <label for=${nodeSelect} class="sr-only">Node for ${name}</label>
    <select id=${nodeSelect}>
      ${ui.store.site.nodes.map((n) => html`<option value=${n.id}>${placeName(ui.store.site, n.id)} · ${n.id}</option>`)}
    </select>
    <button type="button" @click=${() => send("go_to", { node: inputValue(nodeSelect) })}>Send ${name} to node</button>
    <button type="button" class=${out ? "" : "secondary"}
      @click=${() => ui.act(out ? `Put ${name} back in service` : `Take ${name} out of service`, () => ui.api.post(`/api/robots/${encodeURIComponent(name)}/service`, { out_of_service: !out }))}>
      ${out ? `Put ${name} back in service` : `Take ${name} out of service`}</button>
    ${vda
      ? html`<button type="button" class=${paused ? "" : "secondary"}
          @click=${() => ui.act(pause, () => ui.api.post(`/api/robots/${encodeURIComponent(name)}/pause`, { paused: !paused }))}>${pause}</button>`
      : ""}
    ${taskId
      ? html`<button type="button" class="danger" @click=${() => cancelTask(ui, ui.store.tasks.get(taskId) ?? { id: taskId, kind: "task", state: "running", robot: name })}>Cancel ${name}'s task</button>`
      : ""}
  </div>`;
}

const COUNTER_TEXT = {
  frames_rx: "frames received", frames_tx: "frames sent", unknown_id: "unknown ids", bad_frame: "bad frames",
  overflow: "overflows", block_errors: "block errors", send_errors: "send errors", driver_errors: "driver errors",
  record_errors: "record errors", stalls: "stalls", not_online: "frames from modules not online",
  modules_lost: "modules lost", modules_requeried: "modules queried again",
};
const TRAFFIC = new Set(["frames_rx", "frames_tx"]);
const hex = (id) => `0x${id.toString(16).toUpperCase().padStart(2, "0")}`;

/** The robot's CAN buses (its last robocan_status): counters, then one row per module. */
function robocanView(robot) {
  const status = robot.robocan;
  if (!status) return html`<p class="muted">No RoboCAN status received from ${robot.name}.</p>`;
  return html`<p class="muted">RoboCAN status of ${clock(status.at)}.</p>
    ${status.buses.map((bus) => {
      const errors = Object.entries(bus.counters).filter(([k, v]) => !TRAFFIC.has(k) && v > 0);
      return html`<table class="robocan" aria-label=${`RoboCAN modules of ${robot.name} on ${bus.bus}`}>
        <caption>Bus ${bus.bus}: ${bus.counters.frames_rx} frames received, ${bus.counters.frames_tx} sent;
          ${errors.length ? errors.map(([k, v]) => html`<span class="badge bad">${COUNTER_TEXT[k] ?? k}: ${v}</span> `) : "no errors"}</caption>
        <thead><tr><th scope="col">Module</th><th scope="col">Kind</th><th scope="col">Firmware</th><th scope="col">State</th>
          <th scope="col">Frames in / out</th><th scope="col">Errors</th><th scope="col">Faults</th><th scope="col">Lost</th><th scope="col">Queried again</th></tr></thead>
        <tbody>${bus.modules.map((m) => html`<tr data-module=${m.module_id}>
          <td>${m.name} (${hex(m.module_id)})${m.critical ? html` <span class="badge warn">critical</span>` : ""}</td>
          <td>${m.kind ?? "—"}</td><td>${m.firmware ?? "—"}</td>
          <td><span class=${`badge ${m.state === "online" ? "ok" : m.state === "lost" || m.state === "failed" ? "bad" : "warn"}`}>${m.state}</span></td>
          <td>${m.frames_rx} / ${m.frames_tx}</td><td>${m.errors}</td><td>${m.faults}</td><td>${m.lost}</td><td>${m.requeried}</td></tr>`)}</tbody>
      </table>`;
    })}`;
}

export function robotsView(ui) {
  const robots = [...ui.store.robots.values()].sort((a, b) => a.name.localeCompare(b.name));
  return html`<h2>Robots</h2>
    ${robots.map((robot) => {
      const s = robot.state ?? {};
      const info = robot.info ?? {};
      const modules = Object.entries(s.modules ?? {});
      // A lost robot's last robot_state still says what it was doing: the server says offline.
      // A VDA 5050 3.x vehicle asleep (HIBERNATING) is offline to the fleet, not lost.
      const state = linkState(robot);
      const asleep = state === "hibernating";
      const link = [{ online: "ok", lost: "bad" }[state] ?? "warn", state];
      const node = s.node ?? info.node;
      const floor = s.floor ?? info.floor ?? ui.store.site.nodes.find((n) => n.id === node)?.floor;
      return html`<section class="robot-card" aria-labelledby=${`robot-${robot.name}`}>
        <h3 id=${`robot-${robot.name}`}>${robot.name}
          <span class=${`badge ${link[0]}`}>${link[1]}</span>
          ${info.out_of_service ? html`<span class="badge warn">out of service</span>` : ""}
          ${robot.online && s.navigation === "paused" ? html`<span class="badge warn">paused</span>` : ""}</h3>
        <dl class="facts">
          ${evacuationText(ui.store, robot.name) ? html`<dt>Evacuation</dt><dd class="state-evacuation" data-evacuation=${robot.name}>${evacuationText(ui.store, robot.name).replace("evacuation: ", "")}</dd>` : ""}
          <dt>Mode</dt><dd>${robot.online ? `${s.mode ?? info.mode ?? "—"}${waitingFor(ui.store, s) ? `, ${waitingFor(ui.store, s)}` : ""}` : asleep ? "offline, hibernating" : "offline"}</dd>
          <dt>Battery</dt><dd>${percent(s.battery ?? info.battery)}</dd>
          <dt>Pose</dt><dd>${s.floor ? robotPlace(ui.store.site, s) : node ? placeName(ui.store.site, node) : "—"}, ${floor ? floorName(ui.store.site, floor) : "floor —"}${s.floor ? `, x ${s.x.toFixed(1)} m y ${s.y.toFixed(1)} m, ${Math.round((s.theta * 180) / Math.PI)}°` : ""}</dd>
          <dt>Task</dt><dd>${taskText(ui, robot)}</dd>
          <dt>Nets</dt><dd>${(s.nets ?? []).join(", ") || "none"}</dd>
          <dt>RoboCAN modules</dt><dd>${modules.length ? modules.map(([m, st]) => html`<span class=${`badge ${st === "ok" ? "ok" : "bad"}`}>${m}: ${st}</span> `) : "none reported"}</dd>
          <dt>Last errors</dt><dd>${robot.faults.length ? robot.faults.map((f) => html`<div>${clock(f.at)} ${f.kind} ${f.detail ?? ""}</div>`) : "none"}</dd>
        </dl>
        <h4>RoboCAN</h4>
        ${robocanView(robot)}
        ${actions(ui, robot)}
      </section>`;
    })}`;
}
