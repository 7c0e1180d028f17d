// The fire alarm on the console (docs/emergency.md, docs/console.md "Fire alarm"): the banner
// shown on every view while an alarm holds (zone, since when, who or what declared it, the
// robots' evacuation, "Resume service"), "Declare emergency" (with a confirmation), and the
// Building view's section: declare for a zone, raise and clear the simulator's alarm input.
import { html } from "lit-html";
import { confirmAction } from "/lib/confirm.js";
import { inputValue } from "/lib/dom.js";
import { clock } from "/admin/venue.js";
import { evacuationText, floorName } from "/admin/names.js";

/** "the whole site", "floor Ground floor", "areas corridor, gallery". */
export function zoneText(site, zone) {
  if (zone?.floors?.length) return `floor${zone.floors.length > 1 ? "s" : ""} ${zone.floors.map((f) => floorName(site, f)).join(", ")}`;
  if (zone?.areas?.length) return `area${zone.areas.length > 1 ? "s" : ""} ${zone.areas.join(", ")}`;
  return "the whole site";
}

/** Who declared it: a person's token name, or the alarm input ("input:fire_main"). */
function whoText(by) {
  if (!by) return "unknown";
  return by.startsWith("input:") ? `the building's alarm input ${by.slice(6)}` : by;
}

/** Declare an alarm for `zone` after the person confirms it (operator or admin). */
export async function declareEmergency(ui, zone = {}, reason = "") {
  const where = zoneText(ui.store.site, zone);
  const ok = await confirmAction({
    title: `Declare a fire alarm for ${where}?`,
    text: "Every robot there stops at once and drives to its safe spot; no new task starts anywhere, no door is opened and no elevator called for a robot in the zone, and visitor panels show the evacuation screen. Service comes back only when a person resumes it.",
    confirm: "Declare emergency",
    keep: "Do not declare",
  });
  if (!ok) return;
  await ui.act("Declare emergency", async () => {
    ui.store.takeEmergency(await ui.api.post("/api/emergency/declare", {
      zone,
      reason: reason.trim() || `declared from the console by ${ui.me.name}`,
    }));
  });
}

/** Resume service: the server refuses (409, with why) while an alarm input still reads alarm. */
async function resumeService(ui) {
  ui.resumeRefusal = null;
  try {
    const reply = await ui.api.post("/api/emergency/resume");
    ui.store.takeEmergency(reply);
    const n = reply.resumed_tasks?.length ?? 0;
    ui.notice = { ok: true, text: `Resume service: done. ${n} task${n === 1 ? "" : "s"} cut off by the alarm run again in their places.` };
  } catch (err) {
    // Shown while the state it answered lasts (an input cleared since makes it stale).
    const text = err.detail && typeof err.detail === "string" ? err.detail : err.message;
    ui.resumeRefusal = { text, state: ui.store.emergency?.state };
  }
  ui.draw();
}

/** The header's button: the whole site, at once (the Building view offers a zone). */
export function declareButton(ui) {
  const e = ui.store.emergency;
  if (!e || e.state !== "normal" || !ui.operate) return "";
  return html`<button type="button" class="danger" @click=${() => declareEmergency(ui)}>Declare emergency</button>`;
}

function robotsLine(ui, e) {
  const names = Object.keys(e.robots ?? {}).sort();
  if (!names.length) return html`<p>No robot is in the alarm's zone.</p>`;
  const count = (state) => names.filter((n) => e.robots[n].state === state).length;
  const stuck = count("stuck");
  return html`<p>${names.length} robot${names.length === 1 ? "" : "s"} held: ${count("safe")} safe, ${count("moving")} moving to a safe spot, ${count("stopped") + count("ordered")} stopped${stuck ? html`, <strong>${stuck} stuck</strong>` : ""}.</p>
    <ul class="evacuation-list">${names.map((n) => html`<li data-evacuation=${n} data-state=${e.robots[n].state}>${n}: ${evacuationText(ui.store, n)?.replace("evacuation: ", "")}</li>`)}</ul>`;
}

/** The banner on every view while an alarm holds (empty otherwise). */
export function emergencyBanner(ui) {
  const e = ui.store.emergency;
  if (!e || e.state === "normal") return "";
  const site = ui.store.site;
  const zones = (e.zones?.length ? e.zones : [{}]).map((z) => zoneText(site, z)).join("; ");
  const inputs = (e.alarms ?? []).filter((a) => a.reads_alarm !== false);
  const state = e.state === "input_clear"
    ? html`<p><span class="badge ok">alarm input normal</span> The building's alarm is reset: robots stay where they are until a person resumes service.</p>`
    : inputs.length
      ? html`<p>${inputs.map((a) => html`<span class="badge bad">${a.id} (${a.module}/${a.point}) ${a.reads_alarm === null ? "cannot be read" : "reads alarm"}</span> `)}</p>`
      : "";
  return html`<h2 id="emergency-title">Fire alarm: ${zones}</h2>
    <p>Since ${clock(e.since)}, declared by ${whoText(e.declared_by)}${e.reason && !e.declared_by?.startsWith("input:") ? ` (${e.reason})` : ""}. No new task starts; queued tasks wait.</p>
    ${state}
    ${robotsLine(ui, e)}
    ${ui.operate ? html`<div class="actions">
      <button type="button" @click=${() => resumeService(ui)}>Resume service</button>
    </div>` : ""}
    ${ui.resumeRefusal?.state === e.state ? html`<p class="notice error" role="alert">Resume service refused: ${ui.resumeRefusal.text}</p>` : ""}`;
}

/** The simulator's alarm inputs (a demo or test installation): raise or clear each. */
function simulatorAlarms(ui) {
  const alarms = ui.store.site.emergency?.alarms ?? [];
  if (!ui.store.simulator || !alarms.length || !ui.operate) return "";
  const set = (alarm, raised) =>
    ui.act(`${raised ? "Raise" : "Clear"} alarm input ${alarm.id}`, () => ui.api.post("/api/building/simulator/alarm", { alarm: alarm.id, raised }));
  return html`<h4>Alarm inputs on the building simulator</h4>
    <table aria-label="Simulated alarm inputs">
      <thead><tr><th scope="col">Alarm</th><th scope="col">Input</th><th scope="col">Reads</th><th scope="col"><span class="sr-only">Actions</span></th></tr></thead>
      <tbody>${alarms.map((a) => {
        const value = ui.store.building.points.get(`${a.input.module}/${a.input.point}`);
        const reads = value === undefined ? "not read yet" : Number(value) === a.active_when ? "alarm" : "normal";
        return html`<tr><td>${a.id}</td><td>${a.input.module}/${a.input.point}</td><td data-alarm-input=${a.id}>${reads}</td>
          <td><div class="actions"><button type="button" class="danger" @click=${() => set(a, true)}>Raise alarm ${a.id}</button>
            <button type="button" class="secondary" @click=${() => set(a, false)}>Clear alarm ${a.id}</button></div></td></tr>`;
      })}</tbody>
    </table>`;
}

/** The Building view's section: the state, declare for a zone, the simulator's inputs. */
export function emergencySection(ui) {
  const site = ui.store.site;
  const e = ui.store.emergency;
  const choices = [
    ["site", "The whole site", {}],
    ...site.floors.map((f) => [`floor:${f.id}`, `Floor ${floorName(site, f.id)}`, { floors: [f.id] }]),
    ...(site.areas ?? []).map((a) => [`area:${a.id}`, `Area ${a.id}`, { areas: [a.id] }]),
  ];
  const declare = () => {
    const key = inputValue("emergency-zone");
    const zone = choices.find(([k]) => k === key)?.[2] ?? {};
    return declareEmergency(ui, zone, inputValue("emergency-reason"));
  };
  return html`<section aria-labelledby="fire-alarm-title">
    <h3 id="fire-alarm-title">Fire alarm</h3>
    <p id="emergency-state" role="status">${!e ? "Not read yet."
      : e.state === "normal" ? html`<span class="badge ok">normal</span> No alarm holds the building.`
      : html`<span class="badge bad">${e.state === "alarm" ? "alarm" : "alarm input normal, not resumed"}</span> See the banner above.`}</p>
    ${ui.operate ? html`<div class="actions">
      <label for="emergency-zone">Zone</label>
      <select id="emergency-zone">${choices.map(([k, label]) => html`<option value=${k}>${label}</option>`)}</select>
      <label>Reason <input id="emergency-reason" maxlength="300" placeholder="optional"></label>
      <button type="button" class="danger" @click=${declare}>Declare emergency for this zone</button>
    </div>` : ""}
    ${simulatorAlarms(ui)}
  </section>`;
}
