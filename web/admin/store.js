// The console's live state: a REST snapshot at start (and after every reconnect), then hub
// messages. Views read it; "change" events (at most one per animation frame) re-render them.

const MAX_EVENTS = 1000;
const MAX_FINISHED_TASKS = 200;

const isOpen = (alert) => !alert.acked_at && !alert.resolved_at;

export class Store extends EventTarget {
  constructor(api, hub) {
    super();
    this.api = api;
    this.hub = hub;
    this.site = null;
    this.robots = new Map(); // name -> {name, info (GET /api/robots), state (robot_state), online, faults, robocan}
    this.locks = new Map(); // area -> lock view
    this.tasks = new Map(); // id -> task status (GET /api/tasks)
    this.alerts = new Map(); // id -> alert
    this.events = []; // newest last, at most MAX_EVENTS
    this.building = { enabled: false, modules: new Map(), points: new Map() };
    this.doors = new Map(); // door id -> open (bool)
    this.lifts = new Map(); // elevator id -> elevator_state {floor, door_open, state, calls}
    this.simulator = false;
    this.frame = 0;
  }

  changed() {
    if (!this.frame) {
      this.frame = requestAnimationFrame(() => {
        this.frame = 0;
        this.dispatchEvent(new Event("change"));
      });
    }
  }

  emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }

  robot(name) {
    let robot = this.robots.get(name);
    if (!robot) {
      robot = { name, info: null, state: null, online: false, faults: [], robocan: null };
      this.robots.set(name, robot);
    }
    return robot;
  }

  /** Subscribe and load the site; then call reload() (the hub's connect events do too). */
  async start() {
    const on = (type, fn) => this.hub.on(type, (m) => {
      fn(m);
      this.changed();
    });
    on("robot_state", (m) => {
      const robot = this.robot(m.payload.robot);
      robot.state = m.payload;
      robot.online = m.payload.mode !== "offline";
      this.emit("robot_state", m);
    });
    on("robot_connected", (m) => {
      this.robot(m.payload.robot).online = true;
    });
    on("robot_disconnected", (m) => {
      this.robot(m.payload.robot).online = false;
      this.emit("robot_offline", m.payload.robot);
    });
    on("robot_service", (m) => {
      const robot = this.robot(m.payload.robot);
      robot.info = { ...(robot.info ?? {}), out_of_service: m.payload.out_of_service };
    });
    on("robocan_status", (m) => {
      this.robot(m.payload.robot).robocan = { ...m.payload, at: m.timestamp };
    });
    on("robot_fault", (m) => {
      const robot = this.robot(m.payload.robot);
      robot.faults = [{ at: m.timestamp, kind: m.payload.kind, detail: m.payload.detail }, ...robot.faults].slice(0, 5);
    });
    on("lock_changed", (m) => {
      this.locks.set(m.payload.area, m.payload);
      this.emit("lock", m.payload);
    });
    on("task_event", (m) => this.#taskEvent(m.payload, m.timestamp));
    for (const type of ["alert_raised", "alert_acked", "alert_resolved"]) on(type, (m) => this.#alert(m.payload));
    on("event_logged", (m) => {
      this.#addEvents([m.payload]);
      this.inFlight?.push(m.payload);
    });
    on("building_input_changed", (m) => this.#point(m.payload.module, m.payload.point, m.payload.value));
    on("building_module_health", (m) => this.building.modules.set(m.payload.module, m.payload));
    on("door_opened", (m) => this.#door(m.payload.door, true));
    on("door_closed", (m) => this.#door(m.payload.door, false));
    on("elevator_state", (m) => this.#lift(m.payload));
    this.hub.subscribe(
      "robot_state", "robot_connected", "robot_disconnected", "robot_service", "robot_fault", "robocan_status",
      "lock_changed", "task_event", "alert_raised", "alert_acked", "alert_resolved", "event_logged",
      "building_input_changed", "building_module_health", "door_opened", "door_closed",
      "elevator_state",
    );
    this.hub.addEventListener("connect", () => this.reload().catch(() => {}));
    const [site, simulator] = await Promise.all([
      this.api.get("/api/site/map"),
      this.api.get("/api/building/simulator"),
    ]);
    this.site = site.site;
    this.simulator = simulator.configured;
  }

  /** The REST snapshot: what happened while the page was not connected. */
  async reload() {
    this.inFlight = []; // events logged while the snapshot is fetched
    const [robots, locks, tasks, alerts, events, building] = await Promise.all([
      this.api.get("/api/robots"),
      this.api.get("/api/locks"),
      this.api.get("/api/tasks?limit=300"),
      this.api.get("/api/alerts?include_acked=true"),
      this.api.get(`/api/events?latest=true&limit=${MAX_EVENTS}`),
      this.api.get("/api/building"),
    ]);
    for (const info of robots) {
      const robot = this.robot(info.name);
      robot.info = info;
      robot.online = info.online;
      if (info.robocan && !(robot.robocan?.at > info.robocan.at)) robot.robocan = info.robocan;
    }
    for (const view of locks) {
      this.locks.set(view.area, view);
      this.emit("lock", view);
    }
    // Merge, never replace: hub messages that arrived while these requests were in flight
    // are newer than the snapshot.
    for (const task of tasks.tasks) {
      const known = this.tasks.get(task.id);
      if (!known || (known.updated_at ?? 0) <= task.updated_at) this.tasks.set(task.id, task);
    }
    for (const alert of alerts) this.#alert(alert, false);
    const last = events.events.length ? events.events[events.events.length - 1].at : 0;
    this.events = [];
    this.#addEvents([...events.events, ...this.inFlight.filter((row) => row.at > last)]);
    this.inFlight = null;
    this.building.enabled = building.enabled;
    for (const m of building.modules) this.building.modules.set(m.module, m);
    for (const p of building.points) this.#point(p.module, p.point, p.value);
    for (const car of building.elevators ?? []) this.#lift(car);
    this.changed();
  }

  #addEvents(rows) {
    this.events.push(...rows);
    if (this.events.length > MAX_EVENTS) this.events.splice(0, this.events.length - MAX_EVENTS);
    for (const row of rows) {
      if (row.kind === "robot_fault" && row.data?.robot) {
        const robot = this.robot(row.data.robot);
        if (!robot.faults.some((f) => f.at === row.at)) {
          robot.faults = [{ at: row.at, kind: row.data.kind, detail: row.data.detail }, ...robot.faults].slice(0, 5);
        }
      }
    }
  }

  async #taskEvent(p, timestamp) {
    const task = this.tasks.get(p.task_id);
    if (task) {
      Object.assign(task, { state: p.state, robot: p.robot, queue_position: p.queue_position, eta_s: p.eta_s, updated_at: timestamp });
    } else {
      try {
        this.tasks.set(p.task_id, await this.api.get(`/api/tasks/${encodeURIComponent(p.task_id)}`));
      } catch {
        return;
      }
    }
    const finished = [...this.tasks.values()].filter((t) => ["done", "failed", "cancelled"].includes(t.state));
    if (finished.length > MAX_FINISHED_TASKS) {
      finished.sort((a, b) => a.updated_at - b.updated_at);
      for (const t of finished.slice(0, finished.length - MAX_FINISHED_TASKS)) this.tasks.delete(t.id);
    }
    this.changed();
  }

  #point(module, point, value) {
    this.building.points.set(`${module}/${point}`, value);
    for (const door of this.site?.doors ?? []) {
      if (door.is_open && door.is_open.module === module && door.is_open.point === point) this.#door(door.id, Boolean(value));
    }
  }

  #lift(car) {
    this.lifts.set(car.elevator, car);
    if (car.floor) this.emit("lift", car.elevator);
  }

  #door(id, open) {
    this.doors.set(id, open);
    this.emit("door", id);
  }

  /** An alert after a change (hub message or snapshot): the newer of two copies wins; a
   * cause that newly needs attention emits "alert" (the sound). */
  #alert(alert, live = true) {
    const known = this.alerts.get(alert.id);
    if (known && known.updated_at > alert.updated_at) return;
    this.alerts.set(alert.id, alert);
    if (live && isOpen(alert) && !(known && isOpen(known))) this.emit("alert", alert);
  }

  /** Alerts whose cause is there and that nobody acknowledged, last seen first. */
  openAlerts() {
    return [...this.alerts.values()].filter(isOpen).sort((a, b) => b.last_seen - a.last_seen);
  }
}
