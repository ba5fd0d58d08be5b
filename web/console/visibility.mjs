// Map layers of what the cameras can see (server/api/visibility.py, server/visibility_service.py):
//
// - "Coverage: sensors seeing": /api/site/coverage.png, the number of sensors that see each
//   DEM cell, an image on the DEM grid (placed like the relief), with its legend (from
//   /api/site/coverage.json) and an opacity slider;
// - "Viewsheds": each sensor's /api/sensors/{id}/viewshed.geojson?frame=enu as an outline
//   in the sensor's colour (one MultiPolygon feature per sensor, along cell edges);
// - "Blind spots": the unseen areas of /api/site/coverage.json (largest first): their
//   outlines (`outline_enu`, along cell edges) and centroids on the map, and a list (click
//   one to centre the map).
//
// All three are off by default and load the first time they are shown: computing the
// viewsheds takes the server a few seconds the first time, so the page never waits for it.
// One parameter set (target height, range) serves all three: the operator picks it in the
// "Visibility parameters" group; applying it re-asks the layers that are shown (the others
// when next shown). Every load carries a generation number: an answer for parameters that
// are no longer current is dropped, and its requests are aborted.
//
// The applied set is kept in localStorage (PARAMS_KEY) across reloads. What is read back
// is checked like the form's input; anything else (absent, not JSON, wrong types, out of
// range) is removed and the defaults are used. A set the server refuses (422) is removed
// too, so a reload never starts with a refusal.

/* global ol */
import * as api from "./api.mjs";
import { BLIND_COLOUR, SENSOR_COLOURS, withAlpha } from "./palette.mjs";
import { el, fmt } from "./util.mjs";

/** Outline colours of the sensors, by sorted id: the cameras' own colours (palette.mjs). */
export { SENSOR_COLOURS };
/** Target classes, as core/visibility/target_heights.py TARGET_HEIGHT_M (a browser test checks the copy). */
export const TARGETS = [
  { cls: "human", label: "person", height_m: 1.7 },
  { cls: "vehicle", label: "car", height_m: 1.5 },
];
/** The parameters the layers start with (the server's defaults). */
export const DEFAULT_PARAMS = Object.freeze({ target: "human", target_height_m: 1.7, max_range_m: 1000 });
const LAYERS = ["visibility", "viewsheds", "blindspots"];
/** The localStorage key of the operator's parameter set. */
export const PARAMS_KEY = "demtrack.visibility.params";

/** The query string of a parameter set. */
export function paramQuery(p) {
  return new URLSearchParams({ target_height_m: String(p.target_height_m), max_range_m: String(p.max_range_m), mode: "fov" }).toString();
}

/** A parameter set in words: "person 1.7 m · range 1000 m". */
export function describeParams(p) {
  const t = TARGETS.find((x) => x.cls === p.target);
  return `${t ? t.label : "custom"} ${p.target_height_m} m · range ${p.max_range_m} m`;
}

/**
 * Parse the form's values: {params} or {error} (one line). Heights may be 0 (the ground
 * itself); the range must be positive. Upper limits are the server's (its 422 is shown).
 */
export function parseParams(target, heightText, rangeText) {
  const preset = TARGETS.find((x) => x.cls === target);
  const h = preset ? preset.height_m : Number(String(heightText).trim() || NaN);
  const r = Number(String(rangeText).trim() || NaN);
  if (!Number.isFinite(h) || h < 0) return { error: "target height: give a number of metres, 0 or more" };
  if (!Number.isFinite(r) || r <= 0) return { error: "range: give a positive number of metres" };
  return { params: { target: preset ? target : "custom", target_height_m: h, max_range_m: r } };
}

/**
 * The stored parameter set, checked: {target, target_height_m, max_range_m}, or null when
 * there is none or it is not valid (which is then removed). Never throws.
 */
export function loadParams(storage = globalThis.localStorage) {
  let raw = null;
  try {
    raw = storage ? storage.getItem(PARAMS_KEY) : null;
  } catch {
    return null; // storage refused (privacy settings): defaults
  }
  if (raw === null) return null;
  let v = null;
  try {
    v = JSON.parse(raw);
  } catch {
    v = null;
  }
  const ok = v !== null && typeof v === "object" && typeof v.target === "string"
    && (v.target === "custom" || TARGETS.some((t) => t.cls === v.target))
    && typeof v.target_height_m === "number" && typeof v.max_range_m === "number";
  const got = ok ? parseParams(v.target, String(v.target_height_m), String(v.max_range_m)) : {};
  if (!got.params) forgetParams(storage);
  return got.params || null;
}

/** Keep a parameter set for the next page load (quietly does nothing if storage fails). */
export function saveParams(p, storage = globalThis.localStorage) {
  try {
    storage?.setItem(PARAMS_KEY, JSON.stringify({ target: p.target, target_height_m: p.target_height_m, max_range_m: p.max_range_m }));
  } catch {
    /* full or refused: the choice lasts this page only */
  }
}

/** Drop the stored parameter set. */
export function forgetParams(storage = globalThis.localStorage) {
  try {
    storage?.removeItem(PARAMS_KEY);
  } catch {
    /* refused: nothing stored either */
  }
}

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
    this.params = loadParams() || { ...DEFAULT_PARAMS }; // what the next loads ask for
    this.used = { visibility: null, viewsheds: null, blindspots: null }; // what each layer shows
    this.gen = 0; // bumped by every apply(): answers of older generations are dropped
    this.abort = new AbortController();
    this.paramError = "";
    this.summary = null; // coverage.json
    this.summaryP = null;
    this.ui = {};
  }

  /** Is this one of the visibility layers (they share the parameter group)? */
  owns(name) {
    return LAYERS.includes(name);
  }

  layer(name) {
    return { visibility: this.coverage, viewsheds: this.viewsheds, blindspots: this.blind }[name];
  }

  /** The answer of coverage.json for the current parameters (asked once per generation). */
  coverageSummary(ctx) {
    if (!this.summaryP || this.summaryGen !== ctx.gen) {
      this.summaryGen = ctx.gen;
      const p = api.getJSON(`/api/site/coverage.json?${paramQuery(ctx.params)}`, { signal: ctx.signal });
      this.summaryP = p;
      p.catch(() => {
        if (this.summaryP === p) this.summaryP = null; // a later toggle asks again
      });
    }
    return this.summaryP;
  }

  /** Load a layer's data for the current parameters if not yet (a no-op for other layers). */
  ensure(name) {
    const load = { visibility: (c) => this.loadCoverage(c), viewsheds: (c) => this.loadViewsheds(c), blindspots: (c) => this.loadBlind(c) }[name];
    if (!load) return Promise.resolve();
    if (!this.loading[name]) {
      const ctx = { gen: this.gen, params: this.params, signal: this.abort.signal };
      this.setStatus(name, "computing…");
      const p = load(ctx)
        .then((drawn) => {
          if (ctx.gen !== this.gen || !drawn) return; // stale: a newer apply() owns the layer
          this.used[name] = ctx.params;
          this.setStatus(name, "ready");
        })
        .catch((err) => {
          if (ctx.gen !== this.gen) return;
          if (this.loading[name] === p) this.loading[name] = null;
          const why = err.status === 422 ? `server refused: ${err.detail}` : err.detail || err.message || String(err);
          if (err.status === 422) forgetParams(); // a reload starts from the defaults
          this.paramError = why;
          this.setStatus(name, `failed: ${why}`);
        });
      this.loading[name] = p;
      this.showParams();
    }
    return this.loading[name];
  }

  /**
   * Use a new parameter set: the layers shown now are asked again at once, the others when
   * next shown; requests still running for the old set are aborted, their answers dropped.
   */
  apply(params) {
    this.gen += 1;
    this.abort.abort();
    this.abort = new AbortController();
    this.params = { ...params };
    saveParams(this.params);
    this.paramError = "";
    this.loading = {};
    this.summaryP = null;
    const shown = LAYERS.filter((n) => this.layer(n).getVisible());
    for (const n of LAYERS) if (!shown.includes(n)) this.setStatus(n, this.used[n] ? "stale" : "off");
    const all = Promise.all(shown.map((n) => this.ensure(n)));
    this.showParams();
    return all;
  }

  setStatus(name, text) {
    this.status[name] = text;
    const s = this.ui[name]?.status;
    if (s) {
      s.textContent = text === "ready" || text === "off" || text === "stale" ? "" : text;
      s.classList.toggle("error", text.startsWith("failed"));
    }
    const used = this.ui[name]?.used;
    if (used) used.textContent = this.used[name] ? `shown: ${describeParams(this.used[name])}` : "";
    this.showParams();
  }

  /** The parameter group's status line: computing, the server's refusal, or nothing. */
  showParams() {
    const box = this.ui.params;
    if (!box) return;
    const busy = LAYERS.some((n) => this.status[n] === "computing…");
    box.status.textContent = busy ? "computing…" : this.paramError;
    box.status.classList.toggle("error", !busy && !!this.paramError);
    box.root.dataset.busy = busy ? "1" : "0";
    box.root.dataset.gen = String(this.gen);
  }

  async loadCoverage(ctx) {
    const [url, summary] = await Promise.all([
      api.imageURL(`/api/site/coverage.png?${paramQuery(ctx.params)}`, { signal: ctx.signal }),
      this.coverageSummary(ctx),
    ]);
    if (ctx.gen !== this.gen) {
      if (url) URL.revokeObjectURL(url);
      return false;
    }
    this.summary = summary;
    this.siteMap.setImage(this.coverage, url, this.site.dem.bounds_enu);
    const legend = this.ui.visibility?.legend;
    if (legend) {
      legend.replaceChildren(...summary.legend.map((e) => el("span", { "data-count": String(e.count) },
        el("span", { class: "swatch", style: `background:${rgba(e.rgba)}` }),
        `${e.count}${e.or_more ? "+" : ""} sensor${e.count > 1 || e.or_more ? "s" : ""}`)));
      const one = summary.seen_by_at_least["1"];
      legend.append(el("span", { class: "muted" }, `seen by ≥ 1: ${fmt(100 * (one ?? 0), 0)} % of the site`));
    }
    return true;
  }

  async loadViewsheds(ctx) {
    const q = paramQuery(ctx.params);
    const docs = await Promise.all(this.sensorIds.map((id) => api.getJSON(`/api/sensors/${encodeURIComponent(id)}/viewshed.geojson?${q}&frame=enu`, { signal: ctx.signal })));
    if (ctx.gen !== this.gen) return false;
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
    return true;
  }

  async loadBlind(ctx) {
    const summary = await this.coverageSummary(ctx);
    if (ctx.gen !== this.gen) return false;
    this.summary = summary;
    const src = this.blind.getSource();
    src.clear(true);
    const feats = [];
    summary.blind_spots.forEach((b, k) => {
      const [e0, n0, e1, n1] = b.bbox_enu;
      // The outline along cell edges; a server without `outline_enu` gives the box only.
      const rings = b.outline_enu ?? [[[[e0, n0], [e1, n0], [e1, n1], [e0, n1], [e0, n0]]]];
      const box = new ol.Feature(new ol.geom.MultiPolygon(rings));
      box.setProperties({ kind: b.outline_enu ? "outline" : "bbox", spot: k + 1 });
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
    return true;
  }

  /** The "Visibility parameters" group: target class or height, range, Apply. */
  paramControls() {
    const p = this.params;
    const target = el("select", { id: "vis-target", title: "target the layers look for" },
      ...TARGETS.map((t) => el("option", { value: t.cls, text: `${t.label} ${t.height_m} m` })),
      el("option", { value: "custom", text: "custom" }));
    target.value = p.target;
    const height = el("input", { type: "number", id: "vis-height", min: "0", step: "0.1", value: String(p.target_height_m), title: "target height above the surface (m)", disabled: p.target !== "custom" });
    const range = el("input", { type: "number", id: "vis-range", min: "1", step: "50", value: String(p.max_range_m), title: "maximum range from each sensor (m, 3-D)" });
    const status = el("span", { class: "vis-status muted", id: "vis-params-status" });
    const form = el("form", { class: "vis-params", id: "vis-params", novalidate: true, "data-busy": "0", "data-gen": "0" },
      el("div", { class: "vis-params-title", text: "Visibility parameters" }),
      el("label", {}, "target ", target),
      el("label", {}, "height ", height, " m"),
      el("label", {}, "range ", range, " m"),
      el("button", { type: "submit", id: "vis-apply", text: "Apply" }),
      status);
    target.addEventListener("change", () => {
      const t = TARGETS.find((x) => x.cls === target.value);
      height.disabled = !!t;
      if (t) height.value = String(t.height_m);
      else height.focus();
    });
    form.addEventListener("submit", (ev) => {
      ev.preventDefault();
      const got = parseParams(target.value, height.value, range.value);
      if (got.error) {
        this.paramError = got.error;
        status.textContent = got.error;
        status.classList.add("error");
        return;
      }
      this.apply(got.params);
    });
    this.ui.params = { root: form, status, target, height, range };
    return form;
  }

  /** What goes under a layer's row in the layer list (null: the default legend). */
  controls(name) {
    const status = el("span", { class: "vis-status muted" });
    if (name === "visibility") {
      const legend = el("div", { class: "legend", id: "coverage-legend" }, el("span", { class: "muted", text: "loads when shown" }));
      const opacity = el("input", { type: "range", min: "0", max: "1", step: "0.05", value: String(this.coverage.getOpacity()), id: "coverage-opacity", title: "coverage layer opacity" });
      opacity.addEventListener("input", () => this.coverage.setOpacity(Number(opacity.value)));
      const used = el("span", { class: "vis-used muted", "data-used": "visibility" });
      this.ui.visibility = { status, legend, used };
      return el("div", { class: "vis-ctl" }, legend, el("label", { class: "legend" }, el("span", {}, "opacity ", opacity)), el("div", { class: "legend" }, used, status));
    }
    if (name === "viewsheds") {
      const used = el("span", { class: "vis-used muted", "data-used": "viewsheds" });
      this.ui.viewsheds = { status, used };
      return el("div", { class: "legend" }, ...this.sensorIds.map((id) => el("span", {},
        el("span", { class: "swatch line", style: `border-color:${this.colours.get(id)}` }), `${id} sees`)), used, status);
    }
    if (name === "blindspots") {
      const list = el("div", { class: "list", id: "blind-list" });
      const used = el("span", { class: "vis-used muted", "data-used": "blindspots" });
      this.ui.blindspots = { status, list, used };
      return el("div", { class: "legend" },
        el("span", {}, el("span", { class: "swatch dash", style: `border-color:${BLIND_COLOUR}` }), "unseen by every sensor (outline, centroid)"),
        used, status, list);
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
    if (f.get("kind") === "outline" || f.get("kind") === "bbox") {
      return new ol.style.Style({
        stroke: new ol.style.Stroke({ color: BLIND_COLOUR, width: 1.5, lineDash: [5, 4] }),
        fill: new ol.style.Fill({ color: withAlpha(BLIND_COLOUR, 0.1) }),
      });
    }
    return new ol.style.Style({
      image: new ol.style.Circle({ radius: 4, fill: new ol.style.Fill({ color: BLIND_COLOUR }), stroke: new ol.style.Stroke({ color: "#000", width: 1 }) }),
      text: new ol.style.Text({
        text: f.get("label"), font: "bold 11px system-ui, sans-serif", offsetY: -11,
        fill: new ol.style.Fill({ color: "#e6e6e6" }), stroke: new ol.style.Stroke({ color: "rgba(0,0,0,0.85)", width: 3 }),
      }),
    });
  }
}
