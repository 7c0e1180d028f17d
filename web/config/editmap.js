// The editor's floor map: the draft's floor drawn with Leaflet (L.CRS.Simple, metres), plan
// image under it, nodes and points of interest as draggable, focusable markers. It only
// reports what the installer did (events); main.js turns that into edits of the draft.
import * as L from "leaflet";

function icon(className, label, text = "") {
  const safe = document.createElement("span");
  safe.className = "sr-only";
  safe.textContent = label;
  const mark = document.createElement("span");
  mark.className = "mark-text";
  mark.textContent = text;
  return L.divIcon({ className, html: `${mark.outerHTML}${safe.outerHTML}`, iconSize: null });
}

export class EditMap extends EventTarget {
  constructor(element, loadImage) {
    super();
    this.loadImage = loadImage;
    this.map = L.map(element, {
      crs: L.CRS.Simple, minZoom: 0, maxZoom: 7, zoomSnap: 0.25, attributionControl: false,
      doubleClickZoom: false,
    });
    this.map.setView([4, 15], 4);
    this.layer = L.layerGroup().addTo(this.map);
    this.planLayer = L.layerGroup().addTo(this.map);
    this.floor = null;
    this.planKey = null;
    this.planSize = null; // [w, h] px of the current floor's image
    this.images = new Map(); // url -> {url, size}
    this.fitted = new Set();
    // The toolbar above grows and shrinks (calibration form): keep Leaflet's size right.
    new ResizeObserver(() => this.map.invalidateSize({ pan: false })).observe(element);
    this.map.on("click", (e) => this.#emit("mapclick", { x: e.latlng.lng, y: e.latlng.lat }));
  }

  #emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }

  /** Container-relative pixel of a site point (metres), for tests and the benchmark. */
  pointFor(x, y) {
    const p = this.map.latLngToContainerPoint([y, x]);
    const r = this.map.getContainer().getBoundingClientRect();
    return { x: r.left + p.x, y: r.top + p.y };
  }

  async #image(url) {
    if (!this.images.has(url)) {
      const entry = (async () => {
        const blob = await this.loadImage(url);
        const objectUrl = URL.createObjectURL(blob);
        const size = await new Promise((resolve) => {
          const img = new Image();
          img.onload = () => resolve([img.naturalWidth, img.naturalHeight]);
          img.onerror = () => resolve(null);
          img.src = objectUrl;
        });
        return { url: objectUrl, size };
      })();
      this.images.set(url, entry);
    }
    return this.images.get(url);
  }

  static planUrl(floor) {
    if (!floor.plan_image) return null;
    return floor.plan_image.startsWith("uploads/")
      ? `/api/site/${floor.plan_image}`
      : `/api/site/plans/${encodeURIComponent(floor.id)}`;
  }

  /** Draw `floorId` of `doc`; `issues` maps "section/index" to problems; `selected` too. */
  async draw(doc, floorId, issues, selected) {
    this.floor = floorId;
    const floor = doc.floors.find((f) => f.id === floorId);
    await this.#drawPlan(floor);
    this.layer.clearLayers();
    const nodes = new Map(doc.nodes.map((n) => [n.id, n]));
    const here = (id) => nodes.get(id)?.floor === floorId;
    const flagged = (section, i) => (issues.has(`${section}/${i}`) ? " has-issue" : "");
    const isSel = (section, i) => (selected?.section === section && selected?.index === i ? " selected" : "");
    doc.edges.forEach((edge, i) => {
      const a = nodes.get(edge.a);
      const b = nodes.get(edge.b);
      if (!a || !b || a.floor !== floorId || b.floor !== floorId) return;
      const line = L.polyline([[a.y, a.x], [b.y, b.x]], {
        className: `map-edge${edge.one_way ? " one-way" : ""}${edge.steps ? " steps" : ""}${flagged("edges", i)}${isSel("edges", i)}`,
        weight: 6,
      });
      line.bindTooltip(`edge ${edge.a} ${edge.one_way ? "→" : "↔"} ${edge.b}${edge.steps ? " (steps: not step-free)" : ""}`, { sticky: true });
      line.on("click", (e) => {
        L.DomEvent.stop(e);
        this.#emit("select", { section: "edges", index: i });
      });
      line.addTo(this.layer);
    });
    // The fire alarm's escape routes: their nodes' edges drawn over, red and dashed.
    const em = doc.emergency;
    const escape = new Set((doc.areas ?? []).filter((a) => em?.escape_routes?.includes(a.id)).flatMap((a) => a.nodes ?? []));
    doc.edges.forEach((edge) => {
      const a = nodes.get(edge.a);
      const b = nodes.get(edge.b);
      if (!a || !b || a.floor !== floorId || b.floor !== floorId || !escape.has(edge.a) || !escape.has(edge.b)) return;
      L.polyline([[a.y, a.x], [b.y, b.x]], { className: "map-escape", weight: 10, interactive: false }).addTo(this.layer);
    });
    doc.nodes.forEach((node, i) => {
      if (node.floor !== floorId) return;
      const marker = L.marker([node.y, node.x], {
        icon: icon(`edit-node${node.passing_place ? " passing" : ""}${flagged("nodes", i)}${isSel("nodes", i)}`, `node ${node.id}`),
        draggable: true,
        keyboard: true,
        title: `node ${node.id}`,
        riseOnHover: true,
      });
      marker.on("click", (e) => {
        L.DomEvent.stop(e);
        this.#emit("node", { id: node.id, index: i });
      });
      marker.on("dragend", () => {
        const p = marker.getLatLng();
        this.#emit("nodemove", { index: i, x: p.lng, y: p.lat });
      });
      marker.addTo(this.layer);
    });
    doc.pois.forEach((poi, i) => {
      const n = nodes.get(poi.node);
      if (!n || !here(poi.node)) return;
      const marker = L.marker([n.y, n.x], { // drawn beside its node (config.css)
        icon: icon(`edit-poi${flagged("pois", i)}${isSel("pois", i)}`, `point ${poi.name || poi.id}`, "★"),
        draggable: true,
        keyboard: true,
        title: `point ${poi.name || poi.id}`,
        zIndexOffset: 500,
      });
      marker.on("click", (e) => {
        L.DomEvent.stop(e);
        this.#emit("select", { section: "pois", index: i });
      });
      marker.on("dragend", () => {
        const p = marker.getLatLng();
        this.#emit("poidrop", { index: i, x: p.lng, y: p.lat });
      });
      marker.addTo(this.layer);
    });
    const fixtures = [
      ["charging_stations", "edit-station", "⚡"],
      ["wait_points", "edit-wait", "W"],
    ];
    for (const [section, cls, text] of fixtures) {
      (doc[section] ?? []).forEach((item, i) => {
        const n = nodes.get(item.node);
        if (!n || !here(item.node)) return;
        const marker = L.marker([n.y, n.x], { // drawn beside its node (config.css)
          icon: icon(`${cls}${flagged(section, i)}${isSel(section, i)}`, `${section} ${item.id}`, text),
          keyboard: true,
          title: `${section.replace("_", " ")} ${item.id}`,
        });
        marker.on("click", (e) => {
          L.DomEvent.stop(e);
          this.#emit("select", { section, index: i });
        });
        marker.addTo(this.layer);
      });
    }
    (em?.safe_spots ?? []).forEach((spot) => {
      const n = nodes.get(spot);
      if (!n || !here(spot)) return;
      const marker = L.marker([n.y, n.x], { // drawn beside its node (config.css)
        icon: icon(`edit-safe${selected?.section === "emergency" ? " selected" : ""}`, `safe spot ${spot}`, "S"),
        keyboard: true,
        title: `safe spot ${spot}`,
        zIndexOffset: 400,
      });
      marker.on("click", (e) => {
        L.DomEvent.stop(e);
        this.#emit("select", { section: "emergency", index: null });
      });
      marker.addTo(this.layer);
    });
    for (const node of escape) {
      const n = nodes.get(node);
      if (!n || !here(node)) continue;
      L.circleMarker([n.y, n.x], { radius: 12, className: "map-escape-node", interactive: false }).addTo(this.layer);
    }
    if (!this.fitted.has(floorId)) {
      this.fitted.add(floorId);
      const pts = doc.nodes.filter((n) => n.floor === floorId).map((n) => [n.y, n.x]);
      let bounds = pts.length ? L.latLngBounds(pts) : null;
      if (this.planBounds) bounds = bounds ? bounds.extend(this.planBounds) : this.planBounds;
      if (bounds) this.map.fitBounds(bounds.pad(0.1));
    }
  }

  async #drawPlan(floor) {
    const url = floor ? EditMap.planUrl(floor) : null;
    const key = floor ? `${url}|${floor.scale_px_per_m}|${floor.plan_origin}` : null;
    if (key === this.planKey) return;
    this.planKey = key;
    this.planLayer.clearLayers();
    this.planBounds = null;
    this.planSize = null;
    if (!url) return;
    let image;
    try {
      image = await this.#image(url);
    } catch {
      return; // no image yet (unpublished plan of a live floor): the graph alone
    }
    if (!image.size) return;
    const [ox, oy] = floor.plan_origin ?? [0, 0];
    const scale = floor.scale_px_per_m || 20;
    this.planSize = image.size;
    this.planBounds = L.latLngBounds([oy, ox], [oy + image.size[1] / scale, ox + image.size[0] / scale]);
    L.imageOverlay(image.url, this.planBounds, { alt: `Plan of ${floor.name || floor.id}`, interactive: false })
      .addTo(this.planLayer);
  }
}
