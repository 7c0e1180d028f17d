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

/** A node as a person would name the place: "Welcome hall", "charging station station_a",
 * "elevator lift (Ground floor)", "door door_gallery", "near Roman mosaics (First floor)". */
export function placeName(site, nodeId) {
  if (!nodeId) return "—";
  const node = byId(site.nodes, nodeId);
  const poi = (site.pois ?? []).find((p) => p.node === nodeId);
  if (poi) return poi.name || poi.id;
  const station = (site.charging_stations ?? []).find((s) => s.node === nodeId);
  if (station) return `charging station ${station.id}`;
  const lift = (site.elevators ?? []).find((e) => e.stops.some((s) => s.node === nodeId));
  if (lift) return `${elevatorName(site, lift.id)} (${floorName(site, node?.floor)})`;
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
  const floor = floorName(site, node.floor);
  return best ? `near ${best.name || best.id} (${floor})` : `${nodeId} (${floor})`;
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

/** The task a robot runs, by name ("an automatic task" for one the console does not list). */
export function taskLabel(store, id) {
  if (!id) return "none";
  const task = store.tasks.get(id);
  return task ? taskName(store.site, task) : "an automatic task";
}
