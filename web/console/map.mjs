// The site map: OpenLayers in the site's local projection (east/north metres).
//
// The orthophoto and the DEM relief are images on the site grid, so they are static image
// layers over their grids' outer bounds; everything else (roads, sensors, footprints,
// tracks, geolocation hits, markers) is drawn from site-frame coordinates directly.

/* global ol */
import { eventColour, KIND } from "./events.mjs";
import { lastIndexAtOrBefore, positionAt } from "./store.mjs";
import { classColour, HIT_COLOUR, MARKER_COLOUR, MARKER_EDGE_COLOUR, ROAD_COLOUR, SELECTED_COLOUR, sensorColour, withAlpha } from "./palette.mjs";

const TRAIL_S = 30; // seconds of trail behind each live position
const HOLD_LIVE_S = 10;
const HOLD_ENDED_S = 2;

function stroke(color, width, lineDash) {
  return new ol.style.Stroke({ color, width, lineDash });
}

function circle(radius, fill, strokeColor = "#000", strokeWidth = 1.5) {
  return new ol.style.Circle({
    radius,
    fill: new ol.style.Fill({ color: fill }),
    stroke: stroke(strokeColor, strokeWidth),
  });
}

/** ``#rrggbb`` blended half-way to white. */
function fade(hex) {
  const n = parseInt(hex.slice(1), 16);
  const mix = (c) => Math.round(c + 0.45 * (255 - c));
  return `rgb(${mix(n >> 16)},${mix((n >> 8) & 255)},${mix(n & 255)})`;
}

function label(text, color = "#fff", offsetY = -14, font = "bold 12px system-ui, sans-serif") {
  return new ol.style.Text({
    text,
    font,
    offsetY,
    fill: new ol.style.Fill({ color }),
    stroke: stroke("rgba(0,0,0,0.85)", 3),
  });
}

function vectorLayer(name, title, zIndex, style, extra = {}, Layer = ol.layer.Vector) {
  const layer = new Layer({ source: new ol.source.Vector(), style, zIndex, ...extra });
  layer.set("name", name);
  layer.set("title", title);
  return layer;
}

/** A north arrow: the map's y axis is true north and the view never rotates. */
function northArrow() {
  const div = document.createElement("div");
  div.className = "north-arrow ol-unselectable ol-control";
  div.title = "North (site frame y axis = true north)";
  div.innerHTML =
    '<svg viewBox="0 0 24 34" width="24" height="34" aria-label="north arrow">' +
    '<polygon points="12,2 20,26 12,20 4,26" fill="#fff" stroke="#000" stroke-width="1.2"/>' +
    '<polygon points="12,2 12,20 4,26" fill="#222"/>' +
    '<text x="12" y="33" text-anchor="middle" font-size="9" font-weight="bold" fill="#fff">N</text></svg>';
  return new ol.control.Control({ element: div });
}

/** A "home" button under the zoom buttons: the whole site back in view. */
function homeControl(onHome) {
  const div = document.createElement("div");
  div.className = "home-ctl ol-unselectable ol-control";
  const b = document.createElement("button");
  b.type = "button";
  b.id = "map-home";
  b.title = "Zoom to the site (Home)";
  b.setAttribute("aria-label", "zoom to the site");
  b.textContent = "⌂";
  b.addEventListener("click", () => onHome());
  div.append(b);
  return new ol.control.Control({ element: div });
}

/** Pixels within which two hits' labels would overlap (they are then listed as one). */
const LABEL_SPREAD_PX = 16;

export class SiteMap {
  constructor(target, site) {
    this.site = site;
    const b = site.dem.bounds_enu;
    const pad = 0.05 * Math.max(b[2] - b[0], b[3] - b[1]);
    this.extent = [b[0] - pad, b[1] - pad, b[2] + pad, b[3] + pad];
    this.proj = new ol.proj.Projection({ code: "DEMTRACK:ENU", units: "m", extent: this.extent });
    ol.proj.addProjection(this.proj);

    this.ortho = new ol.layer.Image({ zIndex: 0 });
    this.ortho.set("name", "orthophoto");
    this.ortho.set("title", "Orthophoto");
    this.relief = new ol.layer.Image({ zIndex: 1, opacity: 0.3 });
    this.relief.set("name", "relief");
    this.relief.set("title", "DEM relief");

    this.coverage = vectorLayer("coverage", "Camera footprints", 2, (f) => this.coverageStyle(f));
    this.roads = vectorLayer("roads", "Roads", 3, (f, res) => this.roadStyle(f, res));
    // Hundreds of long trajectories that change about once a second: drawn into an image
    // when they (or the view) change, not replayed onto the canvas every frame.
    this.synopsis = vectorLayer("synopsis", "Trajectories (window)", 4, (f) => this.synopsisStyle(f),
      { imageRatio: 1 }, ol.layer.VectorImage);
    this.trails = vectorLayer("tracks", "Live tracks", 6, (f) => this.trackStyle(f), {
      updateWhileAnimating: true,
      updateWhileInteracting: true,
    });
    this.sensors = vectorLayer("sensors", "Sensors", 7, (f) => this.sensorStyle(f));
    this.events = vectorLayer("events", "Events", 8, (f) => this.eventStyle(f));
    this.geo = vectorLayer("geolocation", "Geolocation hits", 9, (f, res) => this.geoStyle(f, res));
    this.markers = vectorLayer("markers", "Markers", 10, (f) => this.markerStyle(f));
    this.selectedId = null;

    this.view = new ol.View({
      projection: this.proj,
      extent: this.extent,
      constrainOnlyCenter: true,
      enableRotation: false,
      maxZoom: 28,
    });
    this.map = new ol.Map({
      target,
      layers: [this.ortho, this.relief, this.coverage, this.roads, this.synopsis, this.trails,
        this.sensors, this.events, this.geo, this.markers],
      view: this.view,
      controls: ol.control.defaults
        .defaults({ rotate: false, attribution: false })
        .extend([new ol.control.ScaleLine({ units: "metric", bar: true, steps: 4, text: true, minWidth: 100 }), northArrow(),
          homeControl(() => this.home())]),
    });
    this.home();

    // What drawing the trajectories' image costs (ms): the map's render after a rebuild of
    // its features (that render draws the image anew). The page refreshes it less often
    // when it is dear.
    this.synopsisRenderMs = 0;
    this.synopsisRebuilt = false;
    let since = null;
    this.map.on("precompose", () => {
      if (this.synopsisRebuilt) since = performance.now();
      this.synopsisRebuilt = false;
    });
    this.map.on("postcompose", () => {
      if (since !== null) this.synopsisRenderMs = performance.now() - since;
      since = null;
    });
  }

  /** The layers the layer list shows (those with a title, other modules' too), top first. */
  layerList() {
    return this.map.getLayers().getArray()
      .filter((l) => l.get("title"))
      .sort((a, b) => (b.getZIndex() ?? 0) - (a.getZIndex() ?? 0));
  }

  setImage(layer, url, bounds) {
    layer.setSource(url ? new ol.source.ImageStatic({ url, imageExtent: bounds, projection: this.proj, interpolate: true }) : null);
  }

  /** The whole site (the DEM's bounds) in view. */
  home() {
    const b = this.site.dem.bounds_enu;
    this.view.fit([b[0], b[1], b[2], b[3]], { padding: [10, 10, 10, 10] });
  }

  /** Whether the whole site is in view (within a few per cent). */
  siteInView() {
    const b = this.site.dem.bounds_enu;
    const size = this.map.getSize();
    if (!size) return false;
    const ext = this.view.calculateExtent(size);
    const tol = 0.05 * Math.max(b[2] - b[0], b[3] - b[1]);
    return ext[0] <= b[0] + tol && ext[1] <= b[1] + tol && ext[2] >= b[2] - tol && ext[3] >= b[3] - tol;
  }

  /** A sensor's own colour (palette.mjs: by rank in sorted id order). */
  sensorColour(id) {
    const ids = this.sensorList ? this.sensorList.map((s) => s.id) : this.site.sensors || [];
    return sensorColour(id, ids);
  }

  // ------------------------------------------------------------------ static layers
  setRoads(geojson) {
    const src = this.roads.getSource();
    src.clear();
    for (const f of geojson.features || []) {
      const feat = new ol.Feature(new ol.geom.LineString(f.geometry.coordinates));
      feat.set("width_m", f.properties.width_m || 6);
      feat.set("name", f.properties.name || "");
      src.addFeature(feat);
    }
  }

  setSensors(sensors) {
    this.sensorList = sensors;
    const pts = this.sensors.getSource();
    pts.clear();
    this.coverage.getSource().clear();
    this.coverageOf = new Map(); // sensor id -> its footprint feature
    for (const s of sensors) {
      const p = new ol.Feature(new ol.geom.Point([s.position_enu[0], s.position_enu[1]]));
      p.set("sensor", s.id);
      p.set("name", s.name);
      pts.addFeature(p);
      this.setFootprint(s.id, [s.position_enu[0], s.position_enu[1]], s.footprint);
    }
  }

  /**
   * Draw sensor `id`'s ground footprint (`footprint.enu`: border points, clockwise from
   * the image's top-left corner) and its field-of-view wedge: the lines from the camera
   * at `xy` to the far corners of the footprint (the top edge's ends), drawn by the same
   * feature (its `wedge`, a second style). Replaces the old one.
   */
  setFootprint(id, xy, footprint) {
    const cov = this.coverage.getSource();
    const old = this.coverageOf.get(id);
    if (old) cov.removeFeature(old);
    this.coverageOf.delete(id);
    const ring = (footprint?.enu || []).map((q) => [q[0], q[1]]);
    if (ring.length < 3) return;
    const corner = Math.floor((footprint.n_rays === ring.length ? footprint.n_rays : ring.length) / 4);
    const wedge = [ring[0], xy, ring[corner]];
    ring.push(ring[0]);
    const poly = new ol.Feature(new ol.geom.Polygon([ring]));
    poly.set("sensor", id);
    poly.set("wedge", wedge);
    cov.addFeature(poly);
    this.coverageOf.set(id, poly);
  }

  /** A `sensor_pose` message: the sensor's footprint and wedge move to the new pose's. */
  setSensorPose(msg) {
    const s = (this.sensorList || []).find((x) => x.id === msg.sensor);
    if (!s || !msg.footprint) return;
    s.footprint = msg.footprint;
    this.setFootprint(s.id, [s.position_enu[0], s.position_enu[1]], msg.footprint);
  }

  // ------------------------------------------------------------------ dynamic layers
  /** Highlight track `id` (or none) on the track layers; restyles them only on a change. */
  setSelected(id) {
    if (id === this.selectedId) return;
    this.selectedId = id;
    this.synopsis.changed();
    this.trails.changed();
  }

  /** Tracks at time `t`: current position, a trail behind it, id label. */
  drawTracks(tracks, t, visible) {
    const src = this.trails.getSource();
    src.clear(true);
    const feats = [];
    for (const tr of tracks) {
      if (!visible(tr)) continue;
      const pts = tr.points;
      if (!pts.length) continue;
      let pos = positionAt(tr, t);
      const tEnd = pts[pts.length - 1].t_s;
      // A track whose newest point is a moment older than the shown time keeps its head
      // there (other sensors' newer fixes set the clock), ended tracks only briefly.
      if (!pos && t > tEnd && t - tEnd <= (tr.live ? HOLD_LIVE_S : HOLD_ENDED_S)) pos = pts[pts.length - 1];
      // Trails: the points in (t - TRAIL_S, t], then the interpolated position.
      const iEnd = lastIndexAtOrBefore(pts, t);
      if (iEnd < 0) continue;
      let i0 = iEnd;
      while (i0 > 0 && pts[i0 - 1].t_s > t - TRAIL_S) i0 -= 1;
      const coords = [];
      for (let i = i0; i <= iEnd; i += 1) coords.push([pts[i].e_m, pts[i].n_m]);
      if (pos) coords.push([pos.e_m, pos.n_m]);
      if (coords.length >= 2) {
        const f = new ol.Feature(new ol.geom.LineString(coords));
        f.set("trackId", tr.id);
        f.set("cls", tr.cls);
        f.set("kind", "trail");
        feats.push(f);
      }
      if (pos) {
        const f = new ol.Feature(new ol.geom.Point([pos.e_m, pos.n_m]));
        f.set("trackId", tr.id);
        f.set("cls", tr.cls);
        f.set("kind", "head");
        f.set("live", tr.live && t >= tEnd - 1e-6);
        feats.push(f);
      }
    }
    src.addFeatures(feats);
  }

  /**
   * Long-term trajectories of a window, solid where tracked, dashed across gaps.
   * @param {Array} trajs  [{id, cls, sensors, parts: [{gap: bool, coords: [[e, n], ...]}]}]
   */
  drawSynopsis(trajs, visible) {
    const src = this.synopsis.getSource();
    src.clear(true);
    this.synopsisRebuilt = true;
    const feats = [];
    for (const tr of trajs) {
      if (!visible(tr) || !tr.parts.length) continue;
      for (const part of tr.parts) {
        if (part.coords.length < 2) continue;
        const f = new ol.Feature(new ol.geom.LineString(part.coords));
        f.setProperties({ trackId: tr.id, cls: tr.cls, gap: part.gap });
        feats.push(f);
      }
      const first = tr.parts[0].coords[0];
      const lastPart = tr.parts[tr.parts.length - 1].coords;
      const a = new ol.Feature(new ol.geom.Point(first));
      a.setProperties({ trackId: tr.id, cls: tr.cls, end: "start" });
      const z = new ol.Feature(new ol.geom.Point(lastPart[lastPart.length - 1]));
      z.setProperties({ trackId: tr.id, cls: tr.cls, end: "end" });
      feats.push(a, z);
    }
    src.addFeatures(feats);
  }

  drawEvents(items) {
    const src = this.events.getSource();
    src.clear(true);
    src.addFeatures(items.map((ev) => {
      const f = new ol.Feature(new ol.geom.Point([ev.e_m, ev.n_m]));
      f.set("kind", ev.kind);
      return f;
    }));
  }

  /** A geolocation answer: the ray's ground trace, every hit, the chosen ones, the road point. */
  drawGeolocation(result, sensor) {
    const src = this.geo.getSource();
    src.clear(true);
    if (!result) return;
    const feats = [];
    const chosen = new Set((result.selected || []).map((h) => `${h.e_m},${h.n_m}`));
    const all = [...(result.hits || [])];
    if (result.road) all.push({ ...result.road, source: "road" });
    if (sensor) {
      const far = all.length ? all.reduce((a, h) => (h.range_m > a.range_m ? h : a)) : null;
      const d = result.ray.direction_enu;
      const o = result.ray.origin_enu;
      const end = far ? [far.e_m, far.n_m] : [o[0] + 300 * d[0], o[1] + 300 * d[1]];
      const ray = new ol.Feature(new ol.geom.LineString([[o[0], o[1]], end]));
      ray.set("kind", "ray");
      feats.push(ray);
    }
    all.forEach((h, k) => {
      const f = new ol.Feature(new ol.geom.Point([h.e_m, h.n_m]));
      f.set("kind", h.source === "road" ? "road" : "hit");
      f.set("chosen", chosen.has(`${h.e_m},${h.n_m}`));
      f.set("label", h.source === "road" ? "road" : String(k + 1));
      f.set("sigma", h.sigma_m);
      f.set("index", k);
      feats.push(f);
      if (chosen.has(`${h.e_m},${h.n_m}`) && h.sigma_m > 0) {
        const c = new ol.Feature(new ol.geom.Circle([h.e_m, h.n_m], h.sigma_m));
        c.set("kind", "sigma");
        feats.push(c);
      }
    });
    src.addFeatures(feats);
  }

  drawMarkers(markers) {
    const src = this.markers.getSource();
    src.clear(true);
    src.addFeatures(markers.map((m) => {
      const f = new ol.Feature(new ol.geom.Point([m.e_m, m.n_m]));
      f.set("name", m.name);
      return f;
    }));
  }

  // -------------------------------------------------------------------------- styles
  roadStyle(f, res) {
    const w = Math.max(2, Math.min(14, f.get("width_m") / res));
    return [
      new ol.style.Style({ stroke: stroke("rgba(40,40,40,0.8)", w + 2) }),
      new ol.style.Style({ stroke: stroke(withAlpha(ROAD_COLOUR, 0.9), w) }),
    ];
  }

  coverageStyle(f) {
    const c = this.sensorColour(f.get("sensor"));
    const area = new ol.style.Style({
      fill: new ol.style.Fill({ color: withAlpha(c, 0.14) }),
      stroke: stroke(withAlpha(c, 0.9), 1.5, [6, 4]),
    });
    const wedge = f.get("wedge");
    if (!wedge) return area;
    // The field of view's edges, camera to far corners: the footprint's second style.
    return [area, new ol.style.Style({
      geometry: new ol.geom.LineString(wedge),
      stroke: stroke(withAlpha(c, 0.8), 1, [2, 4]),
    })];
  }

  sensorStyle(f) {
    return new ol.style.Style({
      image: new ol.style.RegularShape({
        points: 3,
        radius: 9,
        fill: new ol.style.Fill({ color: this.sensorColour(f.get("sensor")) }),
        stroke: stroke("#000", 2),
      }),
      text: label(f.get("sensor"), this.sensorColour(f.get("sensor")), -16),
    });
  }

  trackStyle(f) {
    const sel = f.get("trackId") === this.selectedId;
    const colour = classColour(f.get("cls"));
    if (f.get("kind") === "trail") {
      return [
        new ol.style.Style({ stroke: stroke("rgba(0,0,0,0.6)", sel ? 6 : 4.5) }),
        new ol.style.Style({ stroke: stroke(sel ? SELECTED_COLOUR : colour, sel ? 3.5 : 2.5) }),
      ];
    }
    return new ol.style.Style({
      image: circle(sel ? 8 : 6, sel ? SELECTED_COLOUR : colour, "#000", 2),
      text: label(String(f.get("trackId")), sel ? SELECTED_COLOUR : "#fff", -15),
    });
  }

  synopsisStyle(f) {
    const sel = f.get("trackId") === this.selectedId;
    const colour = sel ? SELECTED_COLOUR : classColour(f.get("cls"));
    if (f.get("end")) {
      return new ol.style.Style({
        image: f.get("end") === "start"
          ? circle(4, "#fff", colour, 2)
          : new ol.style.RegularShape({ points: 4, radius: 5, angle: Math.PI / 4, fill: new ol.style.Fill({ color: colour }), stroke: stroke("#000", 1) }),
        text: f.get("end") === "start" ? label(String(f.get("trackId")), colour, -12, "11px system-ui, sans-serif") : undefined,
      });
    }
    // Thinner and lighter than the live trails, which are drawn over them.
    const dash = f.get("gap") ? [7, 6] : undefined;
    return [
      new ol.style.Style({ stroke: stroke("rgba(0,0,0,0.45)", sel ? 5 : 3.5, dash) }),
      new ol.style.Style({ stroke: stroke(sel ? colour : fade(colour), sel ? 3 : 1.6, dash) }),
    ];
  }

  eventStyle(f) {
    const kind = f.get("kind");
    const colour = eventColour(kind);
    const ended = kind === KIND.TRACK_ENDED;
    return new ol.style.Style({
      image: new ol.style.RegularShape({
        points: ended ? 4 : 5,
        radius: ended ? 6 : 7,
        radius2: ended ? undefined : 3,
        angle: ended ? Math.PI / 4 : 0,
        fill: new ol.style.Fill({ color: colour }),
        stroke: stroke("#000", 1),
      }),
    });
  }

  /** The label of a hit: hits whose labels would overlap at this resolution are listed in
   * one label ("1, 2") at the first of them; the others are drawn without one. */
  hitLabel(f, res) {
    const own = f.get("label");
    const near = [];
    const [x, y] = f.getGeometry().getCoordinates();
    const r = LABEL_SPREAD_PX * res;
    for (const g of this.geo.getSource().getFeatures()) {
      const kind = g.get("kind");
      if (kind !== "hit" && kind !== "road") continue;
      const [gx, gy] = g.getGeometry().getCoordinates();
      if (Math.hypot(gx - x, gy - y) <= r) near.push(g);
    }
    if (near.length <= 1) return own;
    near.sort((a, b) => a.get("index") - b.get("index"));
    if (near[0] !== f) return "";
    return near.map((g) => g.get("label")).join(", ");
  }

  /** The hit labels drawn at the current zoom: [{label, e_m, n_m}] (tests read them). */
  hitLabels() {
    const res = this.view.getResolution();
    return this.geo.getSource().getFeatures()
      .filter((f) => f.get("kind") === "hit" || f.get("kind") === "road")
      .map((f) => ({ label: this.hitLabel(f, res), e_m: f.getGeometry().getCoordinates()[0], n_m: f.getGeometry().getCoordinates()[1] }))
      .filter((x) => x.label);
  }

  geoStyle(f, res) {
    const kind = f.get("kind");
    if (kind === "ray") return new ol.style.Style({ stroke: stroke(HIT_COLOUR, 2, [4, 4]) });
    if (kind === "sigma") {
      return new ol.style.Style({
        fill: new ol.style.Fill({ color: "rgba(255,230,0,0.15)" }),
        stroke: stroke(SELECTED_COLOUR, 1.5),
      });
    }
    const chosen = f.get("chosen");
    return new ol.style.Style({
      image: chosen
        ? circle(8, SELECTED_COLOUR, "#000", 2)
        : kind === "road" ? circle(5, "#ffffff", HIT_COLOUR, 2) : circle(5, HIT_COLOUR, "#000", 1.5),
      text: label(this.hitLabel(f, res), chosen ? SELECTED_COLOUR : "#ffd6f6", -14),
      zIndex: chosen ? 2 : 1,
    });
  }

  markerStyle(f) {
    return new ol.style.Style({
      image: new ol.style.RegularShape({
        points: 4, radius: 8, angle: Math.PI / 4,
        fill: new ol.style.Fill({ color: MARKER_COLOUR }),
        stroke: stroke(MARKER_EDGE_COLOUR, 3),
      }),
      text: label(f.get("name"), MARKER_COLOUR, -16),
    });
  }

  // ------------------------------------------------------------------------- helpers
  /** The track under a map pixel, if any. */
  trackAt(pixel) {
    let found = null;
    this.map.forEachFeatureAtPixel(pixel, (f) => {
      const id = f.get("trackId");
      if (id !== undefined && found === null) found = id;
    }, { hitTolerance: 6, layerFilter: (l) => l === this.trails || l === this.synopsis });
    return found;
  }

  centreOn(e, n) {
    this.view.setCenter([e, n]);
  }

  /** Pixel on the page of a site point (for tests and overlays). */
  pixelOf(e, n) {
    return this.map.getPixelFromCoordinate([e, n]);
  }
}
