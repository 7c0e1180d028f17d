// The floor map of a site: Leaflet with L.CRS.Simple, one map unit = one metre (latitude = y,
// longitude = x, so north is up as in the site file). A floor's plan image is laid under the
// graph at its origin and scale; a floor without an image shows the graph alone. Robots are
// markers with heading, name, state and battery colour, updated at most once per frame.
import * as L from "leaflet";

const AREA_MARGIN_M = 1.2;
const RING_PX = 34; // robots standing together: each ring of spots around their place this much further out
const RING_SPOTS = 6; // spots on the first ring (the k-th ring has k times as many)
const STILL_M = 0.05; // a robot that moved less than this since its last state stood still
const TOGETHER_PX = 44; // closer than this on the screen, a robot's marker or label hides another's
/** Navigator states in which a robot stands and waits for something (robot_state.navigation). */
export const WAITING = new Set(["waiting_area", "waiting_door", "waiting_elevator", "door_blocked"]);
const STATE_COLOURS = { free: "#1b7a3a", held: "#b35900", holder_offline: "#b00020", yielding: "#6a3d9a" };

export function batteryClass(level) {
  if (typeof level !== "number") return "battery-unknown"; // a replay knows no battery
  if (level >= 0.5) return "battery-ok";
  if (level >= 0.2) return "battery-low";
  return "battery-panic";
}

function el(tag, className, text) {
  const node = document.createElement(tag);
  if (className) node.className = className;
  if (text !== undefined) node.textContent = text;
  return node;
}

/**
 * Where spot `n` of a place is, in rings (units of RING_PX, east and north positive): spot 0
 * is the place itself; ring k has RING_SPOTS * k spots, filled east, west, then between.
 * @param {number} n
 * @returns {[number, number]}
 */
export function spotOffset(n) {
  if (!n) return [0, 0];
  let ring = 1;
  let first = 1;
  while (n >= first + RING_SPOTS * ring) {
    first += RING_SPOTS * ring;
    ring += 1;
  }
  const count = RING_SPOTS * ring;
  const i = n - first;
  // East, west, then each half of the ring in turn: 0, 180, 60, 240, 120, 300 degrees (ring 1).
  const half = count / 2;
  const step = Math.floor(i / 2) + (i % 2) * half;
  const angle = (2 * Math.PI * step) / count;
  return [ring * Math.cos(angle), ring * Math.sin(angle)];
}

export class FloorMap extends EventTarget {
  /**
   * @param {HTMLElement} element where the map goes
   * @param {(url: string) => Promise<Blob>} loadImage fetches a plan image with the token
   */
  constructor(element, loadImage) {
    super();
    this.loadImage = loadImage;
    this.map = L.map(element, {
      crs: L.CRS.Simple,
      minZoom: 1,
      maxZoom: 7,
      zoomSnap: 0.25,
      attributionControl: false,
      keyboard: true,
    });
    this.map.setView([0, 0], 3);
    // Doors above the points' labels (Leaflet's tooltip pane is at 650): at 1280x800 the
    // "Welcome hall" label covered door_gallery, so its state (red or green) could not be seen.
    this.map.createPane("doors").style.zIndex = "660";
    this.removed = false; // remove() took it off the page
    this.site = null;
    this.floor = null;
    this.floorLayers = new Map(); // floor id -> L.LayerGroup (plan + graph + fixtures)
    this.areaShapes = new Map(); // area id -> [L.Rectangle]
    this.doorMarks = new Map(); // door id -> L.CircleMarker
    this.liftMarks = new Map(); // elevator id -> [{floor, mark}]
    this.robots = new Map(); // name -> {marker, state, parts}
    this.pending = new Map(); // name -> robot_state message waiting for the next frame
    this.frame = 0;
    this.pathLine = L.layerGroup().addTo(this.map);
    this.robotLayer = L.layerGroup().addTo(this.map);
    this.latencies = new Float64Array(8192); // ms from robot_state timestamp to drawn
    this.latencyCount = 0;
    this.nodes = new Map();
    /** Optional: (robot_state payload) -> text saying what the robot does or waits for. */
    this.describeRobot = null;
    /**
     * Optional: robot name -> its evacuation's state during a fire alarm (the ring's colour).
     * @type {((robot: string) => string | null) | null}
     */
    this.evacuationOf = null;
    /**
     * Optional: robot name -> its link as the page says it ("online", "lost", "hibernating").
     * Given, a robot that is not online stays on the map where it was last seen, drawn as not
     * live (grey, no heading, its label says why); without it (a replay) an offline robot
     * leaves the map.
     * @type {((robot: string) => string) | null}
     */
    this.linkOf = null;
    /** Places where robots are drawn around one: {at, spots: robot name -> spot} */
    this.places = new Set();
    this.moves = 0;
    /** @type {Map<string, any> | null} floor id -> the bounds of its plan image, once drawn */
    this.planBounds = null;
    this.map.on("zoomend", () => this.#spread());
  }

  /** Take the map off its element (the page signed out): the element can hold a new one. */
  remove() {
    this.removed = true;
    cancelAnimationFrame(this.frame);
    this.frame = 0;
    // Leaflet 1.9 ends a zoom animation 250 ms after it began, on a map removed meanwhile too
    // ("reading '_leaflet_pos'" of undefined): end it first.
    const map = /** @type {any} */ (this.map);
    if (map._animatingZoom) map._onZoomTransitionEnd();
    this.map.remove();
  }

  /** Draw a site (the document of GET /api/site/map) and show its first floor. */
  async setSite(site) {
    this.site = site;
    this.nodes = new Map(site.nodes.map((n) => [n.id, n]));
    for (const layer of this.floorLayers.values()) layer.remove();
    this.floorLayers.clear();
    this.areaShapes.clear();
    this.doorMarks.clear();
    this.liftMarks.clear();
    for (const floor of site.floors) this.floorLayers.set(floor.id, L.layerGroup());
    await Promise.all(site.floors.map((f) => this.#drawPlan(f)));
    if (this.removed) return; // taken off the page while its plans loaded
    this.#drawGraph(site);
    this.#drawFixtures(site);
    this.#drawClosed();
    this.showFloor(this.floor && this.floorLayers.has(this.floor) ? this.floor : site.floors[0].id);
  }

  showFloor(floorId) {
    for (const [id, layer] of this.floorLayers) {
      if (id === floorId) layer.addTo(this.map);
      else layer.remove();
    }
    const changed = this.floor !== floorId;
    this.floor = floorId;
    for (const [name, robot] of this.robots) this.#placeRobot(name, robot);
    this.#spread();
    if (changed) {
      this.#fit();
      this.dispatchEvent(new CustomEvent("floor", { detail: floorId }));
    }
  }

  /** Call when the map's container becomes visible: Leaflet measures it again, and the floor
   * is fitted if it could not be while the container was hidden. */
  shown() {
    this.map.invalidateSize();
    if (!this.fitted && this.site) this.#fit();
  }

  #fit() {
    const size = this.map.getSize();
    this.fitted = size.x > 0 && size.y > 0;
    if (!this.fitted) return;
    const points = this.site.nodes.filter((n) => n.floor === this.floor).map((n) => [n.y, n.x]);
    const plan = this.planBounds?.get(this.floor);
    let bounds = points.length ? L.latLngBounds(points) : null;
    if (plan) bounds = bounds ? bounds.extend(plan) : plan;
    if (bounds) this.map.fitBounds(bounds.pad(0.08));
  }

  async #drawPlan(floor) {
    if (!floor.plan_url) return;
    let blob;
    try {
      blob = await this.loadImage(floor.plan_url);
    } catch {
      return; // no plan image: the graph alone is the map
    }
    const url = URL.createObjectURL(blob);
    const size = await new Promise((resolve) => {
      const img = new Image();
      img.onload = () => resolve([img.naturalWidth, img.naturalHeight]);
      img.onerror = () => resolve(null);
      img.src = url;
    });
    if (!size) return;
    const [ox, oy] = floor.plan_origin ?? [0, 0];
    const scale = floor.scale_px_per_m || 20;
    const bounds = L.latLngBounds([oy, ox], [oy + size[1] / scale, ox + size[0] / scale]);
    this.planBounds ??= new Map();
    this.planBounds.set(floor.id, bounds);
    L.imageOverlay(url, bounds, { alt: `Plan of ${floor.name || floor.id}` })
      .addTo(this.floorLayers.get(floor.id))
      .bringToBack();
  }

  #drawGraph(site) {
    for (const edge of site.edges) {
      const a = this.nodes.get(edge.a);
      const b = this.nodes.get(edge.b);
      if (!a || !b || a.floor !== b.floor) continue;
      L.polyline([[a.y, a.x], [b.y, b.x]], {
        className: edge.one_way ? "map-edge one-way" : "map-edge",
        interactive: false,
      }).addTo(this.floorLayers.get(a.floor));
    }
    for (const node of site.nodes) {
      const mark = L.circleMarker([node.y, node.x], {
        radius: node.passing_place ? 5 : 4,
        className: "map-node",
      });
      mark.bindTooltip(node.id, { direction: "top" });
      mark.on("click", () => this.#select("node", node.id));
      mark.addTo(this.floorLayers.get(node.floor));
    }
  }

  #drawFixtures(site) {
    const at = (nodeId) => this.nodes.get(nodeId);
    for (const area of site.areas) {
      const byFloor = new Map();
      for (const id of area.nodes) {
        const n = at(id);
        if (n) byFloor.set(n.floor, [...(byFloor.get(n.floor) ?? []), n]);
      }
      const shapes = [];
      for (const [floorId, nodes] of byFloor) {
        const xs = nodes.map((n) => n.x);
        const ys = nodes.map((n) => n.y);
        const rect = L.rectangle(
          [
            [Math.min(...ys) - AREA_MARGIN_M, Math.min(...xs) - AREA_MARGIN_M],
            [Math.max(...ys) + AREA_MARGIN_M, Math.max(...xs) + AREA_MARGIN_M],
          ],
          { className: "map-area", color: STATE_COLOURS.free, weight: 2, fillOpacity: 0.15 },
        );
        rect.bindTooltip(`area ${area.id}: free`, { sticky: true });
        rect.on("click", () => this.#select("area", area.id));
        rect.addTo(this.floorLayers.get(floorId));
        shapes.push(rect);
      }
      this.areaShapes.set(area.id, shapes);
    }
    for (const poi of site.pois) {
      const n = at(poi.node);
      if (!n) continue;
      const mark = L.circleMarker([n.y + 0.6, n.x + 0.6], { radius: 6, className: "map-poi" });
      mark.bindTooltip(poi.name || poi.id, { direction: "right", permanent: true, className: "map-label" });
      mark.on("click", () => this.#select("poi", poi.id));
      mark.addTo(this.floorLayers.get(n.floor));
    }
    for (const station of site.charging_stations ?? []) {
      const n = at(station.node);
      if (!n) continue;
      const mark = L.circleMarker([n.y, n.x - 0.7], { radius: 5, className: "map-station" });
      mark.bindTooltip(`charger ${station.id}`, { direction: "left" });
      mark.addTo(this.floorLayers.get(n.floor));
    }
    for (const door of site.doors) {
      const n = at(door.node);
      if (!n) continue;
      // Grey until its sensor is read: a door drawn red before anything was read said "closed".
      const mark = L.circleMarker([n.y, n.x], { radius: 8, className: "map-door unknown", pane: "doors" });
      mark.bindTooltip(`door ${door.id}: not read yet`, { direction: "bottom" });
      mark.on("click", () => this.#select("door", door.id));
      mark.addTo(this.floorLayers.get(n.floor));
      this.doorMarks.set(door.id, mark);
    }
    for (const lift of site.elevators) {
      const marks = [];
      for (const stop of lift.stops) {
        const n = at(stop.node);
        if (!n) continue;
        const mark = L.rectangle([[n.y - 0.8, n.x - 0.8], [n.y + 0.8, n.x + 0.8]], {
          className: "map-lift away",
        });
        mark.bindTooltip(`elevator ${lift.id}`, { direction: "right" });
        mark.on("click", () => this.#select("elevator", lift.id));
        mark.addTo(this.floorLayers.get(n.floor));
        marks.push({ floor: stop.floor, mark });
      }
      this.liftMarks.set(lift.id, marks);
    }
    for (const button of site.buttons ?? []) {
      const n = at(button.node);
      if (!n) continue;
      const mark = L.circleMarker([n.y - 0.7, n.x + 0.7], { radius: 5, className: "map-button" });
      mark.bindTooltip(`button ${button.id}`, { direction: "bottom" });
      mark.on("click", () => this.#select("button", button.id));
      mark.addTo(this.floorLayers.get(n.floor));
    }
  }

  #select(kind, id) {
    this.dispatchEvent(new CustomEvent("select", { detail: { kind, id } }));
  }

  /** Lock views of GET /api/locks (or built from traffic events): colour and label areas. */
  setAreaState(view) {
    for (const shape of this.areaShapes.get(view.area) ?? []) {
      shape.setStyle({ color: STATE_COLOURS[view.state] ?? "#555" });
      const who = view.holder ? ` by ${view.holder}` : "";
      const waiting = view.waiting?.length ? `, ${view.waiting.length} waiting` : "";
      shape.setTooltipContent(`area ${view.area}: ${view.state.replace("_", " ")}${who}${waiting}`);
    }
  }

  setDoor(doorId, open) {
    const mark = this.doorMarks.get(doorId);
    if (!mark) return;
    const element = mark.getElement?.();
    mark.options.className = `map-door ${open ? "open" : "closed"}`;
    if (element) element.setAttribute("class", `${mark.options.className} leaflet-interactive`);
    mark.setTooltipContent(`door ${doorId}: ${open ? "open" : "closed"}`);
  }

  /**
   * Where an elevator's car is: at `floorId` (null: at no stop, a car on its way), its door
   * open or not; `text` says it in the page's words for the tooltip (else the floor's id).
   * @param {string} liftId
   * @param {string | null} floorId
   * @param {boolean} doorOpen
   * @param {string} [text]
   */
  setElevator(liftId, floorId, doorOpen, text) {
    for (const { floor, mark } of this.liftMarks.get(liftId) ?? []) {
      const here = floor === floorId;
      const cls = `map-lift ${here ? (doorOpen ? "here open" : "here") : "away"}`;
      mark.options.className = cls;
      mark.getElement?.()?.setAttribute("class", `${cls} leaflet-interactive`);
      mark.setTooltipContent(`elevator ${liftId}: ${text ?? (here ? `here${doorOpen ? ", door open" : ""}` : `at ${floorId}`)}`);
    }
  }

  /** Closed nodes (building modes and trouble, GET /api/closures): node id -> why, each
   * drawn as a red ring on its floor (the console's Building modes view keeps it current). */
  setClosed(closed) {
    this.closed = closed;
    this.#drawClosed();
  }

  #drawClosed() {
    for (const mark of this.closedMarks ?? []) mark.remove();
    this.closedMarks = [];
    if (!this.nodes) return;
    for (const [id, why] of this.closed ?? []) {
      const n = this.nodes.get(id);
      const layer = n && this.floorLayers.get(n.floor);
      if (!layer) continue;
      const mark = L.circleMarker([n.y, n.x], { radius: 11, className: "map-closed" });
      mark.bindTooltip(`${id} closed: ${why}`, { direction: "top" });
      mark.addTo(layer);
      this.closedMarks.push(mark);
    }
  }

  /** The planned path of the selected robot (node ids), drawn on the floors it crosses. */
  setPath(nodeIds) {
    this.pathLine.clearLayers();
    this.pathNodes = nodeIds ?? [];
    this.#drawPath();
  }

  #drawPath() {
    this.pathLine.clearLayers();
    const points = (this.pathNodes ?? []).map((id) => this.nodes.get(id)).filter((n) => n && n.floor === this.floor);
    if (points.length > 1) {
      L.polyline(points.map((n) => [n.y, n.x]), { className: "map-path", interactive: false }).addTo(this.pathLine);
    }
  }

  /**
   * A robot_state message: drawn on the next animation frame (several states, one frame).
   * @param {import("/lib/messages.js").Message<"robot_state">} message
   */
  updateRobot(message) {
    this.pending.set(message.payload.robot, message);
    if (!this.frame) this.frame = requestAnimationFrame(() => this.#drawPending());
  }

  /**
   * A robot's last known place (the snapshot's, for a robot not online since the page loaded):
   * drawn as a state is, not measured as one.
   * @param {any} state  a robot_state payload
   */
  showLastSeen(state) {
    this.updateRobot(/** @type {any} */ ({ type: "robot_state", payload: state, timestamp: 0 }));
  }

  #drawPending() {
    this.frame = 0;
    const now = Date.now();
    for (const [name, message] of this.pending) {
      let robot = this.robots.get(name);
      if (!robot) robot = this.#newRobot(name);
      robot.state = message.payload;
      this.#placeRobot(name, robot);
      if (!message.timestamp) continue; // a last known place from the snapshot, not a live state
      this.latencies[this.latencyCount % this.latencies.length] = now - message.timestamp * 1000;
      this.latencyCount += 1;
    }
    this.pending.clear();
    this.#spread();
    if (this.pathNodes?.length) this.#drawPath();
  }

  #newRobot(name) {
    const icon = L.divIcon({ className: "robot-marker", iconSize: [30, 30], iconAnchor: [15, 15], html: "" });
    const marker = L.marker([0, 0], { icon, keyboard: true, title: `robot ${name}`, riseOnHover: true });
    marker.on("click", () => this.#select("robot", name));
    const parts = { body: el("span", "robot-body"), arrow: el("span", "robot-arrow"), label: el("span", "robot-label", name) };
    parts.body.append(parts.arrow, parts.label);
    const robot = { marker, state: null, parts, shown: false, cls: "" };
    marker.on("add", () => {
      const element = marker.getElement();
      element.replaceChildren(parts.body);
      element.setAttribute("aria-label", `robot ${name}`);
      // Leaflet's marker is focusable (role button) but answers only a keypress of Enter, which
      // a focused marker did not get here: Enter and Space select it, as on any button.
      element.addEventListener("keydown", (event) => {
        if (event.key !== "Enter" && event.key !== " ") return;
        event.preventDefault(); // no page scroll (Space), no second select from Leaflet's keypress
        this.#select("robot", name);
      });
      robot.cls = "";
      robot.link = "";
      this.#style(robot);
    });
    this.robots.set(name, robot);
    return robot;
  }

  #style(robot) {
    const s = robot.state;
    if (!s) return;
    const element = robot.marker.getElement();
    if (!element) return;
    const link = this.linkOf?.(s.robot) ?? "online";
    if (link !== robot.link) {
      robot.link = link;
      const away = link === "online" ? "" : ` (${link})`;
      robot.parts.label.textContent = `${s.robot}${away}`;
      element.setAttribute("aria-label", `robot ${s.robot}${away}`);
    }
    const selected = robot.selected ? " selected" : "";
    if (link !== "online") {
      // Not live: where it was last seen, grey, no heading and no battery colour.
      const cls = `robot-body lost${selected}`;
      if (cls !== robot.cls) robot.parts.body.className = robot.cls = cls;
      element.title = `${s.robot}: ${link}, shown where it was last seen`;
      return;
    }
    const waiting = WAITING.has(s.navigation) ? ` waiting nav-${s.navigation}` : "";
    // During a fire alarm the ring says the robot's evacuation (docs/emergency.md).
    const evacuation = this.evacuationOf?.(s.robot);
    const evac = evacuation ? ` evac evac-${evacuation}` : "";
    const cls = `robot-body mode-${s.mode}${waiting}${evac} ${batteryClass(s.battery)}${selected}`;
    if (cls !== robot.cls) {
      robot.parts.body.className = cls;
      robot.cls = cls;
    }
    robot.parts.arrow.style.transform = `rotate(${(-s.theta * 180) / Math.PI}deg)`;
    const doing = this.describeRobot?.(s) ?? s.mode;
    const battery = typeof s.battery === "number" ? `, battery ${Math.round(s.battery * 100)} %` : "";
    element.title = `${s.robot}: ${doing}${battery}`;
  }

  /** Where to draw a robot: its pose, or its node's place while it has no floor yet (a robot
   * that has not moved since start-up reports its node only). */
  pose(s) {
    if (s.floor) return { floor: s.floor, x: s.x, y: s.y };
    const node = this.nodes.get(s.node);
    return node ? { floor: node.floor, x: node.x, y: node.y } : { floor: null, x: s.x, y: s.y };
  }

  #placeRobot(name, robot) {
    const s = robot.state;
    if (!s) return;
    const pose = this.pose(s);
    // With the page's links known (the console), a robot offline stays where it was last seen.
    const visible = pose.floor === this.floor && (this.linkOf !== null || s.mode !== "offline");
    const at = visible ? [pose.y, pose.x] : null;
    if (at && (!robot.at || Math.hypot(at[0] - robot.at[0], at[1] - robot.at[1]) > STILL_M)) {
      robot.moved = ++this.moves; // the order robots last moved in: who stood somewhere first
    }
    robot.at = at;
    if (visible) {
      robot.marker.setLatLng(robot.at);
      if (!robot.shown) {
        robot.marker.addTo(this.robotLayer);
        robot.shown = true;
      }
      this.#style(robot);
    } else if (robot.shown) {
      robot.marker.remove();
      robot.shown = false;
    }
  }

  /** Robots whose markers or labels would hide each other (closer than TOGETHER_PX on the
   * screen, at its zoom) are drawn around one place, each visible and clickable: the one that
   * stood there first at its own pose, and the place follows it; each next one at the first
   * free spot of rings around it (east, west, then the diagonals). A robot keeps its spot
   * while it stays near the place, so one arriving or leaving never moves the others (a click
   * aimed at one still lands on it); a robot left alone there is drawn where it is. (Robots
   * 0.6 m apart, two tours at one exhibit, were drawn one over the other at a venue's zoom,
   * one label hidden.) */
  #spread() {
    /** @type {Map<string, any>} robot name -> its pose on the screen (layer pixels) */
    const points = new Map();
    for (const [name, robot] of this.robots) {
      if (robot.shown && robot.at) points.set(name, this.map.latLngToLayerPoint(robot.at));
      else if (robot.place) this.#leave(name, robot);
    }
    const near = (a, b) => a.distanceTo(b) < TOGETHER_PX;
    for (const place of this.places) {
      const centre = [...place.spots].find(([, spot]) => spot === 0)?.[0];
      if (centre !== undefined && points.has(centre)) place.at = this.robots.get(centre).at;
      place.point = this.map.latLngToLayerPoint(place.at);
    }
    for (const [name, point] of points) {
      const robot = this.robots.get(name);
      if (robot.place && !near(point, robot.place.point)) this.#leave(name, robot);
    }
    // Robots with no place: the ones that stood still longest first, each to the nearest place
    // it is near, or to a new one with the others near it that have none (a grid of cells as
    // wide as TOGETHER_PX finds them: a fleet of hundreds is not compared pair by pair).
    const loose = [...points.keys()].filter((name) => !this.robots.get(name).place)
      .sort((a, b) => this.robots.get(a).moved - this.robots.get(b).moved || a.localeCompare(b));
    const cells = new Map();
    const cellOf = (point) => [Math.floor(point.x / TOGETHER_PX), Math.floor(point.y / TOGETHER_PX)];
    for (const name of loose) {
      const [cx, cy] = cellOf(points.get(name));
      const key = `${cx},${cy}`;
      if (!cells.has(key)) cells.set(key, []);
      cells.get(key).push(name);
    }
    const neighbours = (point) => {
      const [cx, cy] = cellOf(point);
      const found = [];
      for (let dx = -1; dx <= 1; dx += 1) {
        for (let dy = -1; dy <= 1; dy += 1) found.push(...(cells.get(`${cx + dx},${cy + dy}`) ?? []));
      }
      return found.filter((name) => !this.robots.get(name).place && near(points.get(name), point));
    };
    for (const name of loose) {
      const robot = this.robots.get(name);
      if (robot.place) continue; // it joined one made earlier in this loop
      const point = points.get(name);
      let best = null;
      for (const place of this.places) {
        const d = point.distanceTo(place.point);
        if (d < TOGETHER_PX && (!best || d < best.d)) best = { place, d };
      }
      if (best) {
        this.#join(name, robot, best.place);
        continue;
      }
      const mates = neighbours(point).filter((other) => other !== name);
      if (!mates.length) continue;
      const place = { at: robot.at, point, spots: new Map() };
      this.places.add(place);
      for (const member of [name, ...mates]) this.#join(member, this.robots.get(member), place);
    }
    for (const place of this.places) {
      if (place.spots.size > 1) continue;
      for (const name of place.spots.keys()) this.#leave(name, this.robots.get(name));
      this.places.delete(place);
    }
    const metres = RING_PX / 2 ** this.map.getZoom();
    for (const name of points.keys()) {
      const robot = this.robots.get(name);
      if (robot.place) {
        const [dx, dy] = spotOffset(robot.place.spots.get(name));
        const [y, x] = robot.place.at;
        robot.spread = true;
        robot.marker.setLatLng([y + metres * dy, x + metres * dx]);
      } else if (robot.spread) {
        robot.spread = false;
        robot.marker.setLatLng(robot.at);
      }
    }
  }

  /** ``name`` joins ``place`` at its first free spot. */
  #join(name, robot, place) {
    const taken = new Set(place.spots.values());
    let free = 0;
    while (taken.has(free)) free += 1;
    place.spots.set(name, free);
    robot.place = place;
  }

  #leave(name, robot) {
    robot.place.spots.delete(name);
    robot.place = null;
  }

  /** Take a robot off the map until it reports again (a replay: a robot gone or not there yet). */
  robotOffline(name) {
    const robot = this.robots.get(name);
    if (robot?.state) {
      robot.state = { ...robot.state, mode: "offline" };
      this.#placeRobot(name, robot);
      this.#spread();
    }
  }

  /** Draw every robot's ring again (something the rings show changed, not the robots: a fire
   * alarm's evacuation). */
  restyleRobots() {
    for (const robot of this.robots.values()) this.#style(robot);
  }

  /** Draw one robot again (its link came or went: live, or where it was last seen). */
  restyleRobot(name) {
    const robot = this.robots.get(name);
    if (!robot?.state) return;
    this.#placeRobot(name, robot);
    this.#spread();
  }

  selectRobot(name) {
    for (const [n, robot] of this.robots) {
      robot.selected = n === name;
      this.#style(robot);
    }
  }

  /** Latencies (ms) from robot_state timestamp to drawn since the last call; for the bench. */
  takeLatencies() {
    const n = Math.min(this.latencyCount, this.latencies.length);
    const out = Array.from(this.latencies.subarray(0, n));
    this.latencyCount = 0;
    return out;
  }
}
