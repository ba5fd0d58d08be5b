// One panel per camera: its image, the live boxes with track ids, and click-to-geolocate.
//
// Pixel convention (docs/conventions.md): (u, v) = (column, row) and (0, 0) is the centre
// of the top-left pixel, so the image spans u in [-0.5, width - 0.5]. A click at fraction
// fx of the displayed width is pixel u = fx * width - 0.5.

import { classColour, el, fmt, HIT_COLOUR, SELECTED_COLOUR } from "./util.mjs";

const BOX_WINDOW_S = 0.6; // boxes shown for fixes this recent at the displayed time

export class CameraPanel {
  constructor(sensor, onClick) {
    this.sensor = sensor;
    this.img = el("img", { class: "cam-img", alt: `${sensor.id} image`, draggable: "false" });
    this.canvas = el("canvas", { class: "cam-overlay" });
    this.status = el("span", { class: "cam-status", text: "" });
    this.wrap = el("div", { class: "cam-view", "data-sensor": sensor.id }, this.img, this.canvas);
    this.root = el(
      "section",
      { class: "cam-panel", id: `cam-${sensor.id}` },
      el("header", {}, el("b", { text: sensor.id }), el("span", { class: "muted", text: ` ${sensor.name}` }), this.status),
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

  /** Draw the boxes of `fixes` (with their track ids) and the clicked pixel. */
  draw(fixes, trackOf, selectedId) {
    this.lastDraw = [fixes, trackOf, selectedId];
    this.drawn = []; // {detection_id, bbox, label}: what the panel shows (tests read it)
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
      const tid = trackOf(f.detection_id);
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
      this.drawn.push({ detection_id: f.detection_id, bbox: f.bbox, label: text });
      g.lineWidth = 3;
      g.strokeStyle = "rgba(0,0,0,0.9)";
      g.strokeText(text, x, y - 2);
      g.fillStyle = colour;
      g.fillText(text, x, y - 2);
    }
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
        const tx = x + 12 + 150 > c.width ? x - 150 : x + 12;
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

export { BOX_WINDOW_S };
