// The console's live state: a REST snapshot at start (and after every reconnect), then hub
// messages. Views read it; "change" events (at most one per animation frame) re-render them.

export class Store extends EventTarget {
  constructor(api, hub) {
    super();
    this.api = api;
    this.hub = hub;
    this.site = null;
    this.robots = new Map(); // name -> {name, info (GET /api/robots), state (robot_state), online}
    this.locks = new Map(); // area -> lock view
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

  robot(name) {
    let robot = this.robots.get(name);
    if (!robot) {
      robot = { name, info: null, state: null, online: false };
      this.robots.set(name, robot);
    }
    return robot;
  }

  /** Subscribe and load the snapshot; called once, then the hub's connect events reload it. */
  async start() {
    const hub = this.hub;
    hub.on("robot_state", (m) => {
      const robot = this.robot(m.payload.robot);
      robot.state = m.payload;
      robot.online = m.payload.mode !== "offline";
      this.dispatchEvent(new CustomEvent("robot_state", { detail: m }));
      this.changed();
    });
    hub.on("robot_connected", (m) => {
      this.robot(m.payload.robot).online = true;
      this.changed();
    });
    hub.on("robot_disconnected", (m) => {
      this.robot(m.payload.robot).online = false;
      this.dispatchEvent(new CustomEvent("robot_offline", { detail: m.payload.robot }));
      this.changed();
    });
    hub.on("lock_changed", (m) => {
      this.locks.set(m.payload.area, m.payload);
      this.dispatchEvent(new CustomEvent("lock", { detail: m.payload }));
      this.changed();
    });
    hub.subscribe("robot_state", "robot_connected", "robot_disconnected", "lock_changed");
    hub.addEventListener("connect", () => this.reload());
    this.site = (await this.api.get("/api/site/map")).site;
    await this.reload();
  }

  /** The REST snapshot: what happened while the page was not connected. */
  async reload() {
    const [robots, locks] = await Promise.all([
      this.api.get("/api/robots"),
      this.api.get("/api/locks"),
    ]);
    for (const info of robots) {
      const robot = this.robot(info.name);
      robot.info = info;
      robot.online = info.online;
    }
    for (const view of locks) {
      this.locks.set(view.area, view);
      this.dispatchEvent(new CustomEvent("lock", { detail: view }));
    }
    this.changed();
  }
}
