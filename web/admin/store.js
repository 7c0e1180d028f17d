// The console's live state: a REST snapshot at start (and after every reconnect), then hub
// messages. Views read it; "change" events (at most one per animation frame) re-render them.
import { setVenueZone } from "/admin/venue.js";

const MAX_EVENTS = 20000;
const EVENT_PAGE = 1000;
const TASK_LISTING = "/api/tasks?limit=300";
const TASK_REFRESH_MS = 5000;

const isOpen = (alert) => !alert.acked_at && !alert.resolved_at;

/** @typedef {import("/lib/messages.js").MessageType} MessageType */
/**
 * @template {MessageType} T
 * @typedef {import("/lib/messages.js").Message<T>} Message
 */

export class Store extends EventTarget {
  /** @type {() => void} */
  #markLoaded = () => {};

  /**
   * @param {import("/lib/rest.js").Api} api
   * @param {import("/lib/hub.js").HubClient} hub
   */
  constructor(api, hub) {
    super();
    this.api = api;
    this.hub = hub;
    this.site = null;
    this.robots = new Map(); // name -> {name, info (GET /api/robots), state (robot_state), online, faults, robocan}
    this.locks = new Map(); // area -> lock view
    this.tasks = new Map(); // id -> task status (GET /api/tasks)
    this.alerts = new Map(); // id -> alert
    this.events = []; // newest last, at most MAX_EVENTS (REST rows have an id, live ones not yet)
    this.building = { enabled: false, modules: new Map(), points: new Map() };
    this.doors = new Map(); // door id -> open (bool)
    this.lifts = new Map(); // elevator id -> elevator_state {floor, door_open, state, calls}
    this.simulator = false;
    this.fleet = null; // GET /api/fleet: {paused, by, since, reason}
    this.emergency = null; // GET /api/emergency, kept live (docs/emergency.md)
    this.frame = 0;
    this.error = null; // the last background failure (shown on the page until the next success)
    this.olderEvents = true; // the event log has rows older than this.events[0]
    this.snapshots = 0; // event-log snapshots taken (reloads): a page of older rows is of one
    /** Resolves once the first snapshot is in: a view that chooses from the robots (the
     * monitor's first robot) waits for it, or it chooses from none. @type {Promise<void>} */
    this.loaded = new Promise((resolve) => {
      this.#markLoaded = resolve;
    });
    this.eventPage = EVENT_PAGE; // rows per page of the event log (a test may make it small)
    this.reloading = null; // the reload in flight (a second caller joins it, then runs again)
    this.reloadAgain = false;
    this.inFlight = []; // event_logged rows that arrived while a reload was in flight
    /** "kind:key" -> live messages that set it: a snapshot fetched before one of them came is
     * older than it for that key, so it does not overwrite it (a lift the page saw start to move
     * went back to "not seen" when a reload's late answer landed: CI). */
    this.liveSets = new Map();
    this.tasksTimer = 0;
    this.taskFetch = null;
    this.taskFetchAgain = false;
    this.taskAsked = 0; // task listings requested (a reload's or a refresh's)
    this.taskShown = 0; // the request whose listing the page shows: an older one never replaces it
    this.emergencyFetch = null;
    this.emergencyFetchAgain = false;
    this.stopped = false; // the sign-in ended: nothing of this store changes the page again
  }

  /** The sign-in ended (web/admin/main.js): no more refreshes, live messages or redraws. */
  stop() {
    this.stopped = true;
    clearTimeout(this.tasksTimer);
    cancelAnimationFrame(this.frame);
    this.frame = 0;
  }

  /** A background refresh failed: the page shows why (never swallowed). */
  fail(err) {
    this.error = err instanceof Error ? err.message : String(err);
    console.warn("console refresh failed:", err);
    this.changed();
  }

  changed() {
    if (!this.frame && !this.stopped) {
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
      // links: how many link events (connected, disconnected) the page has seen
      robot = { name, info: null, state: null, online: false, faults: [], robocan: null, links: 0 };
      this.robots.set(name, robot);
    }
    return robot;
  }

  /** Subscribe and load the site; then call reload() (the hub's connect events do too). */
  async start() {
    /**
     * A message type's handler, then the views' redraw.
     * @template {MessageType} T
     * @param {T} type
     * @param {(message: Message<T>) => void} fn
     */
    const on = (type, fn) => this.hub.on(type, (m) => {
      if (this.stopped) return;
      fn(m);
      this.changed();
    });
    on("robot_state", (m) => {
      const robot = this.robot(m.payload.robot);
      // A state the robot sent before its link dropped may be delivered after the drop was
      // announced: it must not bring the robot back online on the page.
      if (robot.downAt && m.timestamp <= robot.downAt) return;
      const online = robot.online;
      robot.state = m.payload;
      robot.online = m.payload.mode !== "offline";
      this.emit("robot_state", m);
      if (online !== robot.online) this.emit("robot_link", robot.name);
    });
    on("robot_connected", (m) => {
      const robot = this.robot(m.payload.robot);
      robot.online = true;
      robot.downAt = 0;
      robot.links += 1;
      this.emit("robot_link", robot.name);
    });
    on("robot_disconnected", (m) => {
      const robot = this.robot(m.payload.robot);
      robot.online = false;
      robot.downAt = m.timestamp;
      robot.links += 1;
      this.emit("robot_link", robot.name);
    });
    on("robot_service", (m) => {
      this.#live(`service:${m.payload.robot}`);
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
      this.#live(`lock:${m.payload.area}`);
      this.locks.set(m.payload.area, m.payload);
      this.emit("lock", m.payload);
    });
    on("task_event", () => this.refreshTasks());
    for (const type of /** @type {const} */ (["alert_raised", "alert_acked", "alert_resolved"])) on(type, (m) => this.#alert(m.payload));
    on("event_logged", (m) => {
      this.#addEvents([m.payload]);
      if (this.reloading) this.inFlight.push(m.payload);
      const row = m.payload;
      if (row.kind === "fleet_paused") this.takeFleet({ paused: true, by: row.data.by, since: row.at, reason: row.data.reason ?? "" });
      if (row.kind === "fleet_resumed") this.takeFleet({ paused: false, by: null, since: null, reason: "" });
    });
    on("building_input_changed", (m) => {
      const { module, point, value } = m.payload;
      this.#live(`point:${module}/${point}`);
      this.#point(module, point, value);
      // An alarm input moved: what it reads decides whether "Resume service" can work.
      if ((this.emergency?.alarms ?? []).some((a) => a.module === module && a.point === point)) this.refreshEmergency();
    });
    on("building_module_health", (m) => {
      this.#live(`module:${m.payload.module}`);
      this.building.modules.set(m.payload.module, m.payload);
    });
    for (const [type, open] of /** @type {const} */ ([["door_opened", true], ["door_closed", false]])) {
      on(type, (m) => {
        this.#live(`door:${m.payload.door}`);
        this.#door(m.payload.door, open);
      });
    }
    on("elevator_state", (m) => {
      this.#live(`lift:${m.payload.elevator}`);
      this.#lift(m.payload);
    });
    // The fire alarm: the state changes (banner), and each robot's evacuation as it reports it.
    on("emergency_changed", (m) => {
      this.#live("emergency");
      this.emergency = { ...(this.emergency ?? {}), ...m.payload };
      this.refreshEmergency();
    });
    on("evacuation_state", (m) => {
      if (!this.emergency) return;
      this.#live("emergency");
      const robots = { ...(this.emergency.robots ?? {}) };
      robots[m.source] = { ...(robots[m.source] ?? {}), ...m.payload, at: m.timestamp };
      this.emergency = { ...this.emergency, robots };
      this.emit("evacuation", m.source);
    });
    this.hub.subscribe(
      "robot_state", "robot_connected", "robot_disconnected", "robot_service", "robot_fault", "robocan_status",
      "lock_changed", "task_event", "alert_raised", "alert_acked", "alert_resolved", "event_logged",
      "building_input_changed", "building_module_health", "door_opened", "door_closed",
      "elevator_state", "emergency_changed", "evacuation_state",
    );
    this.hub.addEventListener("connect", () => this.reload().catch((err) => this.fail(err)));
    const [site, simulator] = await Promise.all([
      this.api.get("/api/site/map"),
      this.api.get("/api/building/simulator"),
    ]);
    setVenueZone(site.timezone); // before the first view draws a time
    this.site = site.site;
    this.simulator = simulator.configured;
  }

  /** The REST snapshot: what happened while the page was not connected. Calls made while
   * one is in flight share it, and one more runs after it (it may have missed their cause). */
  reload() {
    if (this.reloading) {
      this.reloadAgain = true;
      return this.reloading;
    }
    this.reloading = (async () => {
      try {
        do {
          this.reloadAgain = false;
          await this.#reloadOnce();
        } while (this.reloadAgain);
        this.error = null;
      } finally {
        this.reloading = null;
      }
    })();
    return this.reloading;
  }

  async #reloadOnce() {
    this.inFlight = []; // events logged while the snapshot is fetched
    const links = new Map([...this.robots].map(([name, r]) => [name, r.links]));
    const sets = new Map(this.liveSets);
    /** @param {string} key */
    const unchanged = (key) => this.liveSets.get(key) === sets.get(key);
    const taskAsk = ++this.taskAsked;
    const [robots, locks, tasks, alerts, events, building, fleet, emergency] = await Promise.all([
      this.api.get("/api/robots"),
      this.api.get("/api/locks"),
      this.api.get(TASK_LISTING),
      this.api.get("/api/alerts?include_acked=true"),
      this.api.get(`/api/events?latest=true&limit=${this.eventPage}`),
      this.api.get("/api/building"),
      this.api.get("/api/fleet"),
      this.api.get("/api/emergency"),
    ]);
    // A pause, a resume, an alarm or an evacuation step that came live while the snapshot was
    // fetched is newer than it (the page showed the fleet running again, the banner gone).
    if (unchanged("fleet")) this.fleet = fleet;
    if (unchanged("emergency")) this.emergency = emergency;
    else this.refreshEmergency(); // the rest of it (inputs, robots held), fetched after
    for (const info of robots) {
      const robot = this.robot(info.name);
      const service = robot.info?.out_of_service;
      robot.info = unchanged(`service:${info.name}`) ? info : { ...info, out_of_service: service };
      // A link event that came in while the snapshot was fetched is newer than it.
      if (robot.links === (links.get(info.name) ?? 0)) robot.online = info.online;
      if (info.robocan && !(robot.robocan?.at > info.robocan.at)) robot.robocan = info.robocan;
      this.emit("robot_link", info.name);
    }
    for (const view of locks) {
      if (!unchanged(`lock:${view.area}`)) continue;
      this.locks.set(view.area, view);
      this.emit("lock", view);
    }
    this.#setTasks(tasks.tasks, taskAsk);
    for (const alert of alerts) this.#alert(alert, false);
    const last = events.events.length ? events.events[events.events.length - 1].at : 0;
    this.snapshots += 1;
    this.#markLoaded();
    this.events = [];
    this.olderEvents = events.events.length === this.eventPage;
    this.#addEvents([...events.events, ...this.inFlight.filter((row) => row.at > last)]);
    this.inFlight = [];
    this.building.enabled = building.enabled;
    for (const m of building.modules) if (unchanged(`module:${m.module}`)) this.building.modules.set(m.module, m);
    for (const p of building.points) if (unchanged(`point:${p.module}/${p.point}`)) this.#point(p.module, p.point, p.value);
    for (const car of building.elevators ?? []) if (unchanged(`lift:${car.elevator}`)) this.#lift(car);
    this.changed();
  }

  /** The fleet's pause as a live message or this page's own pause or resume said it. */
  takeFleet(view) {
    this.#live("fleet");
    this.fleet = view;
    this.changed();
  }

  /** The emergency state as this page's declare or resume answered it. */
  takeEmergency(view) {
    this.#live("emergency");
    this.emergency = view;
    this.changed();
  }

  /** The emergency state again (after emergency_changed: the robots held, the inputs' values,
   * the cut-off tasks come with the snapshot only). One request at a time, one more after. */
  refreshEmergency() {
    if (this.emergencyFetch) {
      this.emergencyFetchAgain = true;
      return this.emergencyFetch;
    }
    this.emergencyFetch = (async () => {
      try {
        do {
          this.emergencyFetchAgain = false;
          const live = this.liveSets.get("emergency");
          const emergency = await this.api.get("/api/emergency");
          // An evacuation step that came meanwhile is newer: ask again rather than undo it.
          if (live !== this.liveSets.get("emergency")) {
            this.emergencyFetchAgain = true;
            continue;
          }
          this.emergency = emergency;
          for (const name of Object.keys(this.emergency.robots ?? {})) this.emit("evacuation", name);
          this.changed();
        } while (this.emergencyFetchAgain);
      } catch (err) {
        this.fail(err);
      } finally {
        this.emergencyFetch = null;
      }
    })();
    return this.emergencyFetch;
  }

  /** A robot's evacuation while an alarm holds (null otherwise). */
  evacuation(name) {
    const e = this.emergency;
    if (!e || e.state === "normal") return null;
    return e.robots?.[name] ?? null;
  }

  /** One more page of the event log, older than the oldest row shown. A snapshot on its way
   * (a reconnect) is awaited first, and a page that a snapshot overtook is not added: it
   * would sit before rows the snapshot replaced, with a gap the page would not show. */
  async loadOlderEvents() {
    if (this.reloading) await this.reloading;
    const first = this.events.find((row) => row.id !== undefined)?.id;
    if (first === undefined) return;
    const snapshots = this.snapshots;
    const page = await this.api.get(`/api/events?latest=true&before_id=${first}&limit=${this.eventPage}`);
    if (snapshots !== this.snapshots) return;
    this.olderEvents = page.events.length === this.eventPage;
    this.events.unshift(...page.events);
    this.changed();
  }

  /** The tasks as GET /api/tasks lists them. A task_event says how one task changed, not
   * how the others moved in the queue nor its new priority: the listing is fetched again
   * (one request at a time; one more after it when events came in meanwhile), and every
   * few seconds while tasks wait (their ETAs move without events). */
  refreshTasks() {
    if (this.taskFetch) {
      this.taskFetchAgain = true;
      return this.taskFetch;
    }
    this.taskFetch = (async () => {
      try {
        do {
          this.taskFetchAgain = false;
          const ask = ++this.taskAsked;
          this.#setTasks((await this.api.get(TASK_LISTING)).tasks, ask);
        } while (this.taskFetchAgain);
        this.error = null;
      } catch (err) {
        this.fail(err);
      } finally {
        this.taskFetch = null;
      }
    })();
    return this.taskFetch;
  }

  /** The listing of request `ask`, unless the page shows a later request's (a reload's answer
   * that came after a refresh sent later: the task the refresh showed went away again). */
  #setTasks(tasks, ask) {
    if (this.stopped || ask < this.taskShown) return;
    this.taskShown = ask;
    this.tasks = new Map(tasks.map((t) => [t.id, t]));
    clearTimeout(this.tasksTimer);
    if (tasks.some((t) => t.state === "queued")) {
      this.tasksTimer = setTimeout(() => this.refreshTasks(), TASK_REFRESH_MS);
    }
    this.emit("tasks");
    this.changed();
  }

  #addEvents(rows) {
    this.events.push(...rows);
    if (this.events.length > MAX_EVENTS) {
      this.events.splice(0, this.events.length - MAX_EVENTS);
      this.olderEvents = true;
    }
    for (const row of rows) {
      if (row.kind === "robot_fault" && row.data?.robot) {
        const robot = this.robot(row.data.robot);
        if (!robot.faults.some((f) => f.at === row.at)) {
          robot.faults = [{ at: row.at, kind: row.data.kind, detail: row.data.detail }, ...robot.faults].slice(0, 5);
        }
      }
    }
  }

  #point(module, point, value) {
    this.building.points.set(`${module}/${point}`, value);
    for (const door of this.site?.doors ?? []) {
      if (door.is_open && door.is_open.module === module && door.is_open.point === point) this.#door(door.id, Boolean(value));
    }
  }

  /** A live message set ``key`` (see liveSets). @param {string} key */
  #live(key) {
    this.liveSets.set(key, (this.liveSets.get(key) ?? 0) + 1);
  }

  #lift(car) {
    this.lifts.set(car.elevator, car);
    if (car.floor || car.state === "moving") this.emit("lift", car.elevator);
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
