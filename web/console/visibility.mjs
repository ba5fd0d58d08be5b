// Map layers of what the cameras can see (server/routers/visibility.py):
//
// - "Coverage: sensors seeing": /api/site/coverage.png, the number of sensors that see each
//   DEM cell, an image on the DEM grid (placed like the relief), with its legend (from
//   /api/site/coverage.json) and an opacity slider;
// - "Viewsheds": each sensor's /api/sensors/{id}/viewshed.geojson?frame=enu as an outline
//   in the sensor's colour (one MultiPolygon feature per sensor, along cell edges);
// - "Blind spots": the unseen areas of /api/site/coverage.json (largest first): their
//   bounding boxes and centroids on the map, and a list (click one to centre the map).
//
// All three are off by default and load the first time they are shown: computing the
// viewsheds takes the server a few seconds the first time, so the page never waits for it.

/* global ol */
import * as api from "./api.mjs";
import { el, fmt } from "./util.mjs";

/** Outline colours of the sensors, by sorted id (the 3D scene's frustum colours). */
export const SENSOR_COLOURS = ["#ffd700", "#00c8ff", "#ff69b4", "#a0ff78"];
const PARAMS = "target_height_m=1.7&max_range_m=1000&mode=fov";
const BLIND_COLOUR = "#ff4040";

function rgba(c) {
  return `rgba(${c[0]},${c[1]},${c[2]},${(c[3] / 255).toFixed(3)})`;
}

function alpha(hex, a) {
  const n = parseInt(hex.slice(1), 16);
  return `rgba(${n >> 16},${(n >> 8) & 255},${n & 255},${a})`;
}

function vector(name, title, zIndex, style) {
  const layer = new ol.layer.Vector({ source: new ol.source.Vector(), style, zIndex, visible: false });
  layer.set("name", name);
  layer.set("title", title);
  return layer;
}

export class VisibilityLayers {
  /**
   * @param {object} siteMap  the SiteMap (its OpenLayers map and projection)
   * @param {object} site  GET /api/site
   * @param {Array} sensors  GET /api/sensors
   */
  constructor(siteMap, site, sensors) {
    this.siteMap = siteMap;
    this.site = site;
    this.sensorIds = sensors.map((s) => s.id).sort();
    this.colours = new Map(this.sensorIds.map((id, k) => [id, SENSOR_COLOURS[k % SENSOR_COLOURS.length]]));
    this.coverage = new ol.layer.Image({ zIndex: 1.5, opacity: 0.8, visible: false });
    this.coverage.set("name", "visibility");
    this.coverage.set("title", "Coverage: sensors seeing");
    this.viewsheds = vector("viewsheds", "Viewsheds (per sensor)", 2.2, (f) => this.viewshedStyle(f));
    this.blind = vector("blindspots", "Blind spots", 5, (f) => this.blindStyle(f));
    for (const l of [this.coverage, this.viewsheds, this.blind]) siteMap.map.addLayer(l);
    this.status = { visibility: "off", viewsheds: "off", blindspots: "off" };
    this.loading = {};
    this.summary = null; // coverage.json
    this.summaryP = null;
    this.ui = {};
  }

  /** The answer of coverage.json (asked once). */
  coverageSummary() {
    if (!this.summaryP) {
      this.summaryP = api.getJSON(`/api/site/coverage.json?${PARAMS}`).then((s) => (this.summary = s));
      this.summaryP.catch(() => (this.summaryP = null)); // a later toggle asks again
    }
    return this.summaryP;
  }

  /** Load a layer's data the first time it is shown (a no-op for other layers). */
  ensure(name) {
    const load = { visibility: () => this.loadCoverage(), viewsheds: () => this.loadViewsheds(), blindspots: () => this.loadBlind() }[name];
    if (!load) return Promise.resolve();
    if (!this.loading[name]) {
      this.setStatus(name, "computing…");
      this.loading[name] = load()
        .then(() => this.setStatus(name, "ready"))
        .catch((err) => {
          this.loading[name] = null;
          this.setStatus(name, `failed: ${err.message || err}`);
        });
    }
    return this.loading[name];
  }

  setStatus(name, text) {
    this.status[name] = text;
    const s = this.ui[name]?.status;
    if (s) {
      s.textContent = text === "ready" ? "" : text;
      s.classList.toggle("error", text.startsWith("failed"));
    }
  }

  async loadCoverage() {
    const [url, summary] = await Promise.all([api.imageURL(`/api/site/coverage.png?${PARAMS}`), this.coverageSummary()]);
    this.siteMap.setImage(this.coverage, url, this.site.dem.bounds_enu);
    const legend = this.ui.visibility?.legend;
    if (legend) {
      legend.replaceChildren(...summary.legend.map((e) => el("span", { "data-count": String(e.count) },
        el("span", { class: "swatch", style: `background:${rgba(e.rgba)}` }),
        `${e.count}${e.or_more ? "+" : ""} sensor${e.count > 1 || e.or_more ? "s" : ""}`)));
      const one = summary.seen_by_at_least["1"];
      legend.append(el("span", { class: "muted" }, `seen by ≥ 1: ${fmt(100 * (one ?? 0), 0)} % of the site`));
    }
  }

  async loadViewsheds() {
    const docs = await Promise.all(this.sensorIds.map((id) => api.getJSON(`/api/sensors/${encodeURIComponent(id)}/viewshed.geojson?${PARAMS}&frame=enu`)));
    const src = this.viewsheds.getSource();
    src.clear(true);
    const feats = [];
    for (const doc of docs) {
      for (const f of doc.features) {
        const feat = new ol.Feature(new ol.geom.MultiPolygon(f.geometry.coordinates));
        feat.setProperties({ sensor: f.properties.sensor, area_m2: f.properties.area_m2 });
        feats.push(feat);
      }
    }
    src.addFeatures(feats);
  }

  async loadBlind() {
    const summary = await this.coverageSummary();
    const src = this.blind.getSource();
    src.clear(true);
    const feats = [];
    summary.blind_spots.forEach((b, k) => {
      const [e0, n0, e1, n1] = b.bbox_enu;
      const box = new ol.Feature(new ol.geom.Polygon([[[e0, n0], [e1, n0], [e1, n1], [e0, n1], [e0, n0]]]));
      box.setProperties({ kind: "bbox", spot: k + 1 });
      const c = new ol.Feature(new ol.geom.Point(b.centroid_enu));
      c.setProperties({ kind: "centroid", spot: k + 1, label: `B${k + 1}` });
      feats.push(box, c);
    });
    src.addFeatures(feats);
    const list = this.ui.blindspots?.list;
    if (list) {
      const rows = summary.blind_spots.map((b, k) => el("div", {
        "data-spot": String(k + 1),
        title: `bounding box E ${fmt(b.bbox_enu[0], 0)}…${fmt(b.bbox_enu[2], 0)}, N ${fmt(b.bbox_enu[1], 0)}…${fmt(b.bbox_enu[3], 0)} m`,
        onclick: () => this.siteMap.centreOn(b.centroid_enu[0], b.centroid_enu[1]),
      }, el("b", { text: `B${k + 1}` }), el("span", { text: `${fmt(b.area_m2, 0)} m²` }),
      el("span", { class: "muted mono", text: `E ${fmt(b.centroid_enu[0], 0)} N ${fmt(b.centroid_enu[1], 0)}` })));
      const more = summary.blind_spot_count - summary.blind_spots.length;
      if (more > 0) rows.push(el("div", { class: "muted", text: `and ${more} smaller` }));
      if (!rows.length) rows.push(el("div", { class: "muted", text: `none of ${fmt(summary.min_area_m2, 0)} m² or more` }));
      list.replaceChildren(...rows);
    }
  }

  /** What goes under a layer's row in the layer list (null: the default legend). */
  controls(name) {
    const status = el("span", { class: "vis-status muted" });
    if (name === "visibility") {
      const legend = el("div", { class: "legend", id: "coverage-legend" }, el("span", { class: "muted", text: "loads when shown" }));
      const opacity = el("input", { type: "range", min: "0", max: "1", step: "0.05", value: String(this.coverage.getOpacity()), id: "coverage-opacity", title: "coverage layer opacity" });
      opacity.addEventListener("input", () => this.coverage.setOpacity(Number(opacity.value)));
      this.ui.visibility = { status, legend };
      return el("div", { class: "vis-ctl" }, legend, el("label", { class: "legend" }, el("span", {}, "opacity ", opacity)), el("div", { class: "legend" }, status));
    }
    if (name === "viewsheds") {
      this.ui.viewsheds = { status };
      return el("div", { class: "legend" }, ...this.sensorIds.map((id) => el("span", {},
        el("span", { class: "swatch line", style: `border-color:${this.colours.get(id)}` }), `${id} sees (target 1.7 m)`)), status);
    }
    if (name === "blindspots") {
      const list = el("div", { class: "list", id: "blind-list" });
      this.ui.blindspots = { status, list };
      return el("div", { class: "legend" },
        el("span", {}, el("span", { class: "swatch dash", style: `border-color:${BLIND_COLOUR}` }), "unseen by every sensor (box, centroid)"),
        status, list);
    }
    return null;
  }

  viewshedStyle(f) {
    const c = this.colours.get(f.get("sensor")) || "#ffffff";
    return [
      new ol.style.Style({ stroke: new ol.style.Stroke({ color: "rgba(0,0,0,0.55)", width: 3.5 }) }),
      new ol.style.Style({ stroke: new ol.style.Stroke({ color: c, width: 1.8 }), fill: new ol.style.Fill({ color: alpha(c, 0.07) }) }),
    ];
  }

  blindStyle(f) {
    if (f.get("kind") === "bbox") {
      return new ol.style.Style({
        stroke: new ol.style.Stroke({ color: BLIND_COLOUR, width: 1.5, lineDash: [5, 4] }),
        fill: new ol.style.Fill({ color: "rgba(255,64,64,0.08)" }),
      });
    }
    return new ol.style.Style({
      image: new ol.style.Circle({ radius: 4, fill: new ol.style.Fill({ color: BLIND_COLOUR }), stroke: new ol.style.Stroke({ color: "#000", width: 1 }) }),
      text: new ol.style.Text({
        text: f.get("label"), font: "bold 11px system-ui, sans-serif", offsetY: -11,
        fill: new ol.style.Fill({ color: "#ffd0d0" }), stroke: new ol.style.Stroke({ color: "rgba(0,0,0,0.85)", width: 3 }),
      }),
    });
  }
}
