// The site's names for what the server calls by id: tours, points, stations, doors, elevators
// and the places robots stand at (a node is named by the point, station, door or elevator
// there, else by the nearest point of interest on its floor).

const byId = (list, id) => (list ?? []).find((x) => x.id === id);

export function floorName(site, floor) {
  const f = byId(site.floors, floor);
  return f?.name || floor || "";
}

export function tourName(site, id) {
  return byId(site.tours, id)?.name || id;
}

export function poiName(site, id) {
  return byId(site.pois, id)?.name || id;
}

export function doorName(site, id) {
  const door = byId(site.doors, id);
  return door?.name || `door ${id}`;
}

export function elevatorName(site, id) {
  const lift = byId(site.elevators, id);
  return lift?.name || `elevator ${id}`;
}

/** A robot's link as the console says it everywhere (Robots view, map, Fleet): "online";
 * "hibernating" for a VDA 5050 3.x vehicle asleep (offline to the fleet, not lost); "lost" for
 * one seen before and offline now; "never connected". */
export function linkState(robot) {
  if (!robot) return "never connected";
  if (robot.online) return "online";
  if (robot.state?.navigation === "hibernating") return "hibernating";
  return robot.state || robot.info?.last_seen ? "lost" : "never connected";
}

/** Where the console draws a robot: its last robot_state, else (not heard from since the page
 * loaded) the node the server last knew it at; null when there is neither. */
export function lastKnown(robot) {
  if (robot.state) return robot.state;
  const node = robot.info?.node;
  return node && robot.info?.last_seen ? { robot: robot.name, node, floor: null, x: 0, y: 0, theta: 0, mode: "offline", battery: robot.info.battery } : null;
}

/** A door's state as its sensor last said it, the same words on every view. */
export function doorState(store, id) {
  if (!store.doors.has(id)) return "not read yet";
  return store.doors.get(id) ? "open" : "closed";
}

/** A node as a person would name the place: "Welcome hall", "charging station station_a",
 * "elevator lift", "door door_gallery", "near Roman mosaics" (the floor is said beside it). */
export function placeName(site, nodeId) {
  if (!nodeId) return "—";
  const node = byId(site.nodes, nodeId);
  const poi = (site.pois ?? []).find((p) => p.node === nodeId);
  if (poi) return poi.name || poi.id;
  const station = (site.charging_stations ?? []).find((s) => s.node === nodeId);
  if (station) return `charging station ${station.id}`;
  const lift = (site.elevators ?? []).find((e) => e.stops.some((s) => s.node === nodeId));
  if (lift) return elevatorName(site, lift.id);
  const door = (site.doors ?? []).find((d) => d.node === nodeId);
  if (door) return doorName(site, door.id);
  if (!node) return nodeId;
  let best = null;
  let bestD = Infinity;
  for (const p of site.pois ?? []) {
    const at = byId(site.nodes, p.node);
    if (!at || at.floor !== node.floor) continue;
    const d = Math.hypot(at.x - node.x, at.y - node.y);
    if (d < bestD) {
      best = p;
      bestD = d;
    }
  }
  return best ? `near ${best.name || best.id}` : `${nodeId} (${floorName(site, node.floor)})`;
}

const AT_NODE_M = 0.6; // closer than this to a node, a robot is at it (the map's "together")

/** Where a robot is, in the site's words, from its pose when it has one: at the node it stands
 * on ("Welcome hall"), else near the node it is closest to ("near elevator lift"); from its
 * last node when it reported none yet. Its last node alone said "Welcome hall" all the way to
 * the lift, 6 m on. */
export function robotPlace(site, s) {
  if (!s) return "—";
  if (!s.floor || typeof s.x !== "number" || typeof s.y !== "number") return placeName(site, s.node);
  let best = null;
  let bestD = Infinity;
  for (const n of site.nodes ?? []) {
    if (n.floor !== s.floor) continue;
    const d = Math.hypot(n.x - s.x, n.y - s.y);
    if (d < bestD) {
      best = n;
      bestD = d;
    }
  }
  if (!best) return placeName(site, s.node);
  const place = placeName(site, best.id);
  return bestD < AT_NODE_M || place.startsWith("near ") ? place : `near ${place}`;
}

/** What a task does, in the site's words: "Tour: Highlights", "Go to: Roman mosaics". */
export function taskName(site, task) {
  const p = task.params ?? {};
  if (task.kind === "tour") return `Tour: ${tourName(site, p.tour)}`;
  if (task.kind === "go_to_poi") return `Go to: ${poiName(site, p.poi)}`;
  if (task.kind === "go_to") return `Go to: ${placeName(site, p.node)}`;
  if (task.kind === "charge") return p.station ? `Charge at ${placeName(site, byId(site.charging_stations, p.station)?.node)}` : "Charge";
  return [task.kind, ...Object.values(p)].join(" ");
}

/** The id of the task a robot runs: what its last robot_state says (none when idle), else the
 * snapshot's (a robot not heard from since the page loaded). The snapshot's is never a
 * fallback for an idle robot: it named the task the robot ran at sign-in long after it ended. */
export function robotTaskId(robot) {
  return robot.state ? robot.state.task_id ?? null : robot.info?.task_id ?? null;
}

/** The task a robot runs, by name ("an automatic task" for one the console does not list). */
export function taskLabel(store, id) {
  if (!id) return "none";
  const task = store.tasks.get(id);
  return task ? taskName(store.site, task) : "an automatic task";
}

const WAITS = { waiting_door: "door", door_blocked: "door", waiting_area: "area", waiting_elevator: "elevator" };

function neighbours(site, nodeId) {
  const out = new Set([nodeId]);
  for (const e of site.edges ?? []) {
    if (e.a === nodeId) out.add(e.b);
    if (e.b === nodeId) out.add(e.a);
  }
  return out;
}

/** What a robot stands and waits for, from robot_state.navigation, the lock views and the
 * site around its node ("waiting for door door_gallery to open", "blocked: door door_gallery
 * did not open", "waiting for area corridor (held by R2)"); null when it does not wait. */
export function waitingFor(store, s) {
  const what = WAITS[s?.navigation];
  if (!what) return null;
  const site = store.site;
  if (what === "area") {
    const lock = [...store.locks.values()].find((l) => (l.waiting ?? []).includes(s.robot));
    if (!lock) return "waiting for a restricted area";
    return `waiting for area ${lock.area}${lock.holder ? ` (held by ${lock.holder})` : ""}`;
  }
  const near = neighbours(site, s.node);
  if (what === "door") {
    const door = (site.doors ?? []).find((d) => near.has(d.node));
    const name = door ? doorName(site, door.id) : "a door";
    return s.navigation === "door_blocked" ? `blocked: ${name} did not open` : `waiting for ${name} to open`;
  }
  const lift = (site.elevators ?? []).find((e) => e.stops.some((st) => near.has(st.node)));
  return `waiting for ${lift ? elevatorName(site, lift.id) : "the elevator"}`;
}

/** "at Welcome hall", or "near Roman mosaics" for a place that is near one ("at near" was said). */
export function atPlace(place) {
  return place.startsWith("near ") ? place : `at ${place}`;
}

/** A robot's evacuation while a fire alarm holds it, as staff read it ("evacuation: moving to
 * its safe spot Charging station B", "evacuation: stuck near Roman mosaics: the way is
 * blocked"); null when no alarm holds it (docs/emergency.md, docs/console.md). */
export function evacuationText(store, name) {
  const e = store.evacuation?.(name);
  if (!e) return null;
  const site = store.site;
  const spot = e.safe_spot ? placeName(site, e.safe_spot) : null;
  const at = e.node ? atPlace(placeName(site, e.node)) : "at an unknown place";
  switch (e.state) {
    case "ordered":
      return spot ? `evacuation: ordered to its safe spot ${spot}` : `evacuation: no safe spot${e.why ? ` (${e.why})` : ""}`;
    case "stopped":
      return `evacuation: stopped ${at}`;
    case "moving":
      return spot ? `evacuation: moving to its safe spot ${spot}` : "evacuation: moving to its safe spot";
    case "safe":
      return `evacuation: safe ${at}`;
    case "stuck":
      return `evacuation: stuck ${at}${e.why ? `: ${e.why}` : ""}`;
    default:
      return `evacuation: ${e.state}`;
  }
}

/** A robot's mode as the console says it: its evacuation during an alarm, the wait when it
 * waits, else its mode; "out of service" first when staff took it out (the map's tooltip and
 * the Fleet view said "idle" alone, as for a robot free to take a task). */
export function robotDoing(store, s) {
  const doing = evacuationText(store, s?.robot) ?? waitingFor(store, s) ?? s?.mode ?? "—";
  return store.robots?.get(s?.robot)?.info?.out_of_service ? `out of service, ${doing}` : doing;
}
