// One panel per camera: its image, the live boxes with track ids, and click-to-geolocate.
//
// Pixel convention (docs/conventions.md): (u, v) = (column, row) and (0, 0) is the centre
// of the top-left pixel, so the image spans u in [-0.5, width - 0.5]. A click at fraction
// fx of the displayed width is pixel u = fx * width - 0.5.

import { classColour, HIT_COLOUR, SELECTED_COLOUR } from "./palette.mjs";
import { el, fmt } from "./util.mjs";

const BOX_WINDOW_S = 0.6; // boxes shown for fixes this recent at the displayed time
/** A new box takes the track of the same sensor's box it overlaps best (IoU at least
 * LINK_MIN_IOU) among those of the last LINK_MAX_GAP_S seconds, until its own track
 * arrives (tracks lag the fixes by the server's reorder lag, 0.6 s). */
const LINK_MAX_GAP_S = 2.0;
const LINK_MIN_IOU = 0.2;

/** Intersection over union of two [u0, v0, u1, v1] boxes. */
export function iou(a, b) {
  const w = Math.min(a[2], b[2]) - Math.max(a[0], b[0]);
  const h = Math.min(a[3], b[3]) - Math.max(a[1], b[1]);
  if (w <= 0 || h <= 0) return 0;
  const inter = w * h;
  const area = (q) => Math.max(0, q[2] - q[0]) * Math.max(0, q[3] - q[1]);
  return inter / (area(a) + area(b) - inter);
}

/**
 * The track of each fix of `shown` (a sensor's boxes on screen): the track whose points
 * carry its detection id, else (its track not yet arrived) the track of the box it
 * continues: the best-overlapping earlier box of the same sensor and class within
 * LINK_MAX_GAP_S, itself labelled either way. `recent` is the sensor's kept fixes (oldest
 * first). Returns Map detection_id -> {tid, provisional}.
 */
export function linkBoxes(recent, shown, trackOf) {
  const out = new Map();
  if (!shown.length) return out;
  const t0 = Math.min(...shown.map((f) => f.t_s)) - LINK_MAX_GAP_S;
  const tEnd = Math.max(...shown.map((f) => f.t_s));
  let open = []; // [{bbox, t_s, cls, tid, provisional}]: the latest box of each chain
  const walk = recent.filter((f) => f.t_s >= t0 && f.t_s <= tEnd + 1e-6);
  for (const f of shown) if (!walk.includes(f)) walk.push(f);
  walk.sort((a, b) => a.t_s - b.t_s);
  for (const f of walk) {
    open = open.filter((o) => f.t_s - o.t_s <= LINK_MAX_GAP_S);
    let tid = trackOf(f.detection_id);
    let provisional = false;
    let best = null;
    let bestIou = LINK_MIN_IOU;
    for (const o of open) {
      if (o.cls !== f.cls || o.t_s >= f.t_s - 1e-9) continue;
      const q = iou(o.bbox, f.bbox);
      if (q >= bestIou) {
        bestIou = q;
        best = o;
      }
    }
    if (tid === undefined && best && best.tid !== undefined) {
      tid = best.tid;
      provisional = true;
    }
    if (best) open.splice(open.indexOf(best), 1);
    open.push({ bbox: f.bbox, t_s: f.t_s, cls: f.cls, tid, provisional });
    out.set(f.detection_id, { tid, provisional });
  }
  return out;
}

export class CameraPanel {
  constructor(sensor, onClick) {
    this.sensor = sensor;
    this.img = el("img", { class: "cam-img", alt: `${sensor.id} image`, draggable: "false" });
    this.canvas = el("canvas", { class: "cam-overlay" });
    this.status = el("span", { class: "cam-status", text: "" });
    this.pose = el("span", { class: "cam-pose", text: "" });
    this.wrap = el("div", { class: "cam-view", "data-sensor": sensor.id }, this.img, this.canvas);
    this.root = el(
      "section",
      { class: "cam-panel", id: `cam-${sensor.id}` },
      el("header", {}, el("span", { class: "swatch cam-swatch", title: `${sensor.id}'s colour on the map and in 3D` }), el("b", { text: sensor.id }), el("span", { class: "muted", text: ` ${sensor.name}` }), this.pose, this.status),
      this.wrap,
    );
    this.click = null; // {u, v, result}
    this.wrap.addEventListener("click", (ev) => {
      const r = this.wrap.getBoundingClientRect();
      const u = ((ev.clientX - r.left) / r.width) * sensor.width_px - 0.5;
      const v = ((ev.clientY - r.top) / r.height) * sensor.height_px - 0.5;
      onClick(this, Math.round(u * 100) / 100, Math.round(v * 100) / 100);
    });
    this.wrap.style.aspectRatio = `${sensor.width_px} / ${sensor.height_px}`;
    new ResizeObserver(() => this.resize()).observe(this.wrap);
    this.lastDraw = null;
    this.setPose(sensor.pose || sensor);
  }

  /**
   * Show a pose: pan, tilt (degrees) and zoom as the horizontal field of view. `pose` is a
   * `sensor_pose` message, the sensor's `pose` or the sensor itself (its fixed pan and
   * tilt); an hfov of null is the calibrated lens's (from fx, the intrinsics).
   */
  setPose(pose) {
    const fx = this.sensor.intrinsics?.fx;
    const lens = fx ? (2 * Math.atan(this.sensor.width_px / 2 / fx) * 180) / Math.PI : null;
    const hfov = pose.hfov_deg ?? lens;
    const parts = [`pan ${fmt(pose.pan_deg, 1)}°`, `tilt ${fmt(pose.tilt_deg, 1)}°`];
    if (hfov !== null && hfov !== undefined) parts.push(`hfov ${fmt(hfov, 1)}°`);
    this.pose.textContent = parts.join(" · ");
    this.pose.dataset.pan = String(pose.pan_deg);
    this.pose.title = pose.t_s !== undefined ? "pose telemetry (newest)" : "fixed pose (site.json)";
  }

  setImage(url) {
    if (url) this.img.src = url;
    else this.img.replaceWith(el("div", { class: "cam-img cam-missing", text: "no image for this camera" }));
  }

  resize() {
    const r = this.wrap.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    this.canvas.width = Math.max(1, Math.round(r.width * dpr));
    this.canvas.height = Math.max(1, Math.round(r.height * dpr));
    if (this.lastDraw) this.draw(...this.lastDraw);
  }

  /** The camera's own colour (palette.mjs), on its header and its border. */
  setColour(colour) {
    this.colour = colour;
    this.root.style.setProperty("--cam-colour", colour);
  }

  /**
   * Draw the boxes of `fixes` and the clicked pixel. `trackOf(detection_id)` gives a box's
   * track: a number, {tid, provisional} (a box whose own track has not arrived yet, labelled
   * with the track of the box it continues), or undefined. `show(fix, tid)` says whether the
   * filters let it through (default: all).
   */
  draw(fixes, trackOf, selectedId, show = () => true) {
    this.lastDraw = [fixes, trackOf, selectedId, show];
    this.drawn = []; // {detection_id, bbox, label, provisional}: what the panel shows (tests read it)
    this.nFiltered = 0;
    const c = this.canvas;
    const g = c.getContext("2d");
    g.clearRect(0, 0, c.width, c.height);
    const sx = c.width / this.sensor.width_px;
    const sy = c.height / this.sensor.height_px;
    const px = (u) => (u + 0.5) * sx;
    const py = (v) => (v + 0.5) * sy;
    const fontPx = Math.max(10, Math.round(11 * (window.devicePixelRatio || 1)));
    g.font = `bold ${fontPx}px system-ui, sans-serif`;
    g.textBaseline = "bottom";
    for (const f of fixes) {
      const link = trackOf(f.detection_id);
      const tid = link !== null && typeof link === "object" ? link.tid : link;
      const provisional = !!(link && typeof link === "object" && link.provisional);
      if (!show(f, tid)) {
        this.nFiltered += 1;
        continue;
      }
      const sel = tid !== undefined && tid === selectedId;
      const colour = sel ? SELECTED_COLOUR : classColour(f.cls);
      const [u0, v0, u1, v1] = f.bbox;
      const x = px(u0);
      const y = py(v0);
      const minPx = 6 * (window.devicePixelRatio || 1);
      const w = Math.max(minPx, (u1 - u0) * sx);
      const h = Math.max(minPx, (v1 - v0) * sy);
      g.lineWidth = sel ? 3 : 2;
      g.strokeStyle = "rgba(0,0,0,0.7)";
      g.strokeRect(x - 1, y - 1, w + 2, h + 2);
      g.strokeStyle = colour;
      g.strokeRect(x, y, w, h);
      const text = tid !== undefined ? `#${tid}` : f.tracked ? "…" : "·";
      this.drawn.push({ detection_id: f.detection_id, bbox: f.bbox, label: text, provisional });
      g.lineWidth = 3;
      g.strokeStyle = "rgba(0,0,0,0.9)";
      g.strokeText(text, x, y - 2);
      g.fillStyle = colour;
      g.fillText(text, x, y - 2);
    }
    if (this.nFiltered) this.root.dataset.filtered = String(this.nFiltered);
    else delete this.root.dataset.filtered;
    if (this.click) {
      const x = px(this.click.u);
      const y = py(this.click.v);
      g.strokeStyle = "#000";
      g.lineWidth = 4;
      cross(g, x, y);
      g.strokeStyle = HIT_COLOUR;
      g.lineWidth = 2;
      cross(g, x, y);
      const res = this.click.result;
      if (res) {
        const chosen = new Set((res.selected || []).map((h) => `${h.e_m},${h.n_m}`));
        // At most a few lines over the image: the chosen hit(s) first; the table has all.
        const hits = res.hits || [];
        const lines = [];
        hits.forEach((h, k) => {
          if (chosen.has(`${h.e_m},${h.n_m}`)) lines.push(`▶ hit ${k + 1}: ${fmt(h.range_m, 1)} m`);
        });
        if (res.road && res.rule === "road") lines.push(`▶ road: ${fmt(res.road.range_m, 1)} m`);
        if (hits.length) lines.push(`  ${hits.length} terrain hit${hits.length > 1 ? "s" : ""}, ${fmt(hits[0].range_m, 0)}–${fmt(hits[hits.length - 1].range_m, 0)} m`);
        else lines.push("no terrain hit");
        g.textBaseline = "top";
        const lh = fontPx + 3;
        const textW = Math.max(...lines.map((line) => g.measureText(line).width));
        const tx = Math.max(2, x + 12 + textW > c.width ? x - 12 - textW : x + 12);
        lines.forEach((line, k) => {
          g.lineWidth = 3;
          g.strokeStyle = "rgba(0,0,0,0.9)";
          g.strokeText(line, tx, y + 6 + k * lh);
          g.fillStyle = line.startsWith("▶") ? SELECTED_COLOUR : "#ffd6f6";
          g.fillText(line, tx, y + 6 + k * lh);
        });
      }
    }
  }
}

function cross(g, x, y) {
  g.beginPath();
  g.moveTo(x - 10, y);
  g.lineTo(x - 3, y);
  g.moveTo(x + 3, y);
  g.lineTo(x + 10, y);
  g.moveTo(x, y - 10);
  g.lineTo(x, y - 3);
  g.moveTo(x, y + 3);
  g.lineTo(x, y + 10);
  g.stroke();
}

/**
 * Sizes the camera panels so that all of them fit the column's height (one or two
 * columns, whichever shows the images larger): opening the detail panel below them shrinks
 * the images rather than pushing a camera out of sight. Re-fitted whenever the column
 * changes size.
 */
export function fitCameras(root, panels) {
  const fit = () => {
    const list = [...panels()];
    if (!list.length) return;
    const gap = 6;
    const pad = 12;
    const W = root.clientWidth - pad;
    const H = root.clientHeight - pad;
    const head = 18;
    const n = list.length;
    let best = { cols: 1, w: 0 };
    for (const cols of [1, 2]) {
      const rows = Math.ceil(n / cols);
      const cellW = (W - gap * (cols - 1)) / cols - 2;
      let w = cellW;
      for (const p of list) {
        const aspect = p.sensor.width_px / p.sensor.height_px;
        const cellH = (H - gap * (rows - 1)) / rows - head - (p.extraHeight || 0) - 2; // ptz.mjs strip
        w = Math.min(w, cellH * aspect);
      }
      if (w > best.w + 1) best = { cols, w };
    }
    const w = Math.max(120, Math.floor(best.w));
    root.style.gridTemplateColumns = `repeat(${best.cols}, minmax(0, 1fr))`;
    for (const p of list) p.wrap.style.width = `${w}px`;
  };
  new ResizeObserver(fit).observe(root);
  return fit;
}

export { BOX_WINDOW_S, LINK_MAX_GAP_S };
