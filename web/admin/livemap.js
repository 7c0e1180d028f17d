// The console's map view controller: the live floor map (robots from robot_state, areas, doors,
// elevators, evacuation rings), what a click selects, and the selected robot's planned path.
// Its toolbar and details panel are drawn by web/admin/views/map.js.
import { lastKnown, linkState, robotDoing } from "/admin/names.js";
import { carText } from "/admin/views/building.js";
import { FloorMap } from "/lib/map.js";

/**
 * Create the map in `element` and keep it in step with the store; a selection or a floor change
 * redraws the console.
 * @param {any} ui  the console state (web/admin/console.js): its store, api, selected, draw
 * @param {HTMLElement} element
 * @returns {FloorMap}
 */
export function mountMap(ui, element) {
  const { store, api } = ui;
  const map = new FloorMap(element, (url) => api.get(url));
  map.describeRobot = (s) => robotDoing(store, s);
  map.evacuationOf = (name) => store.evacuation(name)?.state ?? null;
  map.linkOf = (name) => linkState(store.robots.get(name));
  store.addEventListener("evacuation", () => map.restyleRobots());
  let pathKey = "";
  store.addEventListener("robot_state", (/** @type {CustomEvent} */ e) => {
    map.updateRobot(e.detail);
    const s = e.detail.payload;
    if (ui.selected?.kind === "robot" && ui.selected.id === s.robot) {
      const key = `${s.node}|${s.task_id}|${s.poi}`;
      if (key !== pathKey) {
        pathKey = key;
        showPath(s.robot);
      }
    }
  });
  // A robot whose link came or went: drawn live again, or where it was last seen, as lost (one
  // lost before the page loaded: at the node the server last knew it at).
  store.addEventListener("robot_link", (/** @type {CustomEvent} */ e) => {
    const robot = store.robots.get(e.detail);
    const drawn = map.robots.get(e.detail);
    if (drawn?.state) map.restyleRobot(e.detail);
    else if (robot && !robot.online && lastKnown(robot)) map.showLastSeen(lastKnown(robot));
  });
  store.addEventListener("lock", (/** @type {CustomEvent} */ e) => map.setAreaState(e.detail));
  store.addEventListener("door", (/** @type {CustomEvent} */ e) => map.setDoor(e.detail, store.doors.get(e.detail)));
  store.addEventListener("lift", (/** @type {CustomEvent} */ e) => showCar(store, map, e.detail));
  map.addEventListener("select", async (/** @type {CustomEvent} */ e) => {
    ui.selected = e.detail;
    ui.draw(); // the details at once; a robot's path follows when the server answers
    if (e.detail.kind === "robot") {
      map.selectRobot(e.detail.id);
      await showPath(e.detail.id);
    } else {
      map.selectRobot(null);
      map.setPath([]);
    }
  });
  map.addEventListener("floor", () => ui.draw());

  /** The selected robot's planned path: from where it is to its task's goal. */
  async function showPath(name) {
    const robot = store.robots.get(name);
    const task = robot?.state?.task_id ? store.tasks.get(robot.state.task_id) : null;
    const goal = task ? goalNode(store.site, task, robot.state.poi, robot.state.node) : null;
    if (!goal || !robot.state.node) return map.setPath([]);
    try {
      const path = await api.get(`/api/paths?from_node=${encodeURIComponent(robot.state.node)}&to_node=${encodeURIComponent(goal)}`);
      map.setPath(path.nodes);
    } catch {
      map.setPath([]);
    }
  }
  return map;
}

/**
 * Draw what the store knew before the map had its site: areas, doors, elevators.
 * @param {any} store
 * @param {FloorMap} map
 */
export function showBuilding(store, map) {
  for (const view of store.locks.values()) map.setAreaState(view);
  for (const [id, open] of store.doors) map.setDoor(id, open);
  for (const id of store.lifts.keys()) showCar(store, map, id);
}

/**
 * Draw where an elevator's car is: at its floor, or at none while it moves (it left the floor
 * it was last at: the map drew it there, "here", for the whole ride); its tooltip says it as
 * the Building view does ("moving to First floor (last at Ground floor)").
 * @param {any} store
 * @param {FloorMap} map
 * @param {string} id
 */
function showCar(store, map, id) {
  const car = store.lifts.get(id);
  // Before the site is loaded (a message may come first) there is nothing to draw it on:
  // showBuilding draws it then.
  if (!store.site || !car || car.state === "unknown") return;
  map.setElevator(id, car.state === "moving" ? null : car.floor, car.door_open, carText(car, store.site));
}

/**
 * The node a task is heading for (a tour: the point after the one it showed last, or the one
 * after that when the robot already stands there); null when it has none.
 * @param {any} site
 * @param {{params?: Record<string, any>}} task
 * @param {string | null} poi  the point the robot showed last
 * @param {string | null} [here]  the node the robot stands on
 * @returns {string | null}
 */
export function goalNode(site, task, poi, here = null) {
  const p = task.params ?? {};
  if (p.node) return p.node;
  const poiNode = (id) => site.pois.find((x) => x.id === id)?.node;
  if (p.poi) return poiNode(p.poi);
  if (p.station) return site.charging_stations.find((s) => s.id === p.station)?.node;
  if (p.tour) {
    const tour = site.tours.find((t) => t.id === p.tour);
    if (!tour) return null;
    let next = Math.min((poi ? tour.points.indexOf(poi) : -1) + 1, tour.points.length - 1);
    if (poiNode(tour.points[next]) === here) next = Math.min(next + 1, tour.points.length - 1);
    return poiNode(tour.points[next]);
  }
  return null;
}
