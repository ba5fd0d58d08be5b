// The left sidebar's layer list (a toggle and a legend per map layer, the visibility
// layers' controls) and filters (class, sensor, track ids).

import { ACTIVITY_COLOUR, eventColour, KIND } from "./events.mjs";
import { drawLists } from "./lists.mjs";
import { HIT_COLOUR, MARKER_COLOUR, ROAD_COLOUR, SELECTED_COLOUR } from "./palette.mjs";
import { filtersChanged, parseTrackIds, timeline, ui } from "./state.mjs";
import { $, classColour, el } from "./util.mjs";

/** Whether the layer's toggle is ticked (true before the list is built). */
export function layerChecked(name) {
  const box = document.querySelector(`#layers input[data-layer="${name}"]`);
  return box ? box.checked : true;
}

const LEGENDS = {
  tracks: [["swatch", "vehicle", "vehicle"], ["swatch", "human", "human"]],
  synopsis: [["swatch line", "#ccc", "tracked"], ["swatch dash", "#ccc", "hand-off gap"]],
  sensors: "per-sensor",
  coverage: "per-sensor",
  geolocation: [["swatch", HIT_COLOUR, "terrain hit"], ["swatch", SELECTED_COLOUR, "chosen hit, 1σ"]],
  events: [["swatch", eventColour(KIND.TRACK_CONFIRMED), "track confirmed"],
    ["swatch", eventColour(KIND.TRACK_ENDED), "track ended"],
    ["swatch", ACTIVITY_COLOUR, "activity (loiter, meet, convoy)"],
    ["swatch", eventColour(KIND.HANDOFF), "hand-off"]],
  markers: [["swatch", MARKER_COLOUR, "kept marker"]],
  roads: [["swatch line", ROAD_COLOUR, "road"]],
};

/** A row per map layer: its toggle, then its legend or its own controls. */
export function buildLayerList() {
  const root = $("#layers");
  root.replaceChildren();
  for (const layer of ui.map.layerList()) {
    const name = layer.get("name");
    const box = el("input", { type: "checkbox", checked: layer.getVisible(), "data-layer": name, id: `layer-${name}` });
    box.addEventListener("change", () => {
      layer.setVisible(box.checked);
      if (box.checked) ui.vis.ensure(name); // the visibility layers load when first shown
      ui.dirty = true;
    });
    // One parameter group (target, range) above the first of the visibility layers.
    if (ui.vis.owns(name) && !root.querySelector("#vis-params")) root.append(ui.vis.paramControls());
    root.append(el("div", { class: "layer-row" }, box, el("label", { for: `layer-${name}`, text: layer.get("title") })));
    const controls = ui.vis.controls(name);
    let legend = LEGENDS[name];
    if (legend === "per-sensor") { // each camera in its own colour (palette.mjs)
      const what = name === "sensors" ? "" : " footprint";
      legend = ui.sensors.map((s) => ["swatch", ui.map.sensorColour(s.id), `${s.id}${what}`]);
    }
    if (controls) {
      root.append(controls);
    } else if (legend) {
      root.append(el("div", { class: "legend" }, ...legend.map(([cls, colour, text]) => {
        const c = colour === "vehicle" || colour === "human" ? classColour(colour) : colour;
        const style = cls.includes("line") || cls.includes("dash") ? `border-color:${c}` : `background:${c}`;
        return el("span", {}, el("span", { class: cls, style }), text);
      })));
    }
  }
}

/** The class and sensor checkboxes and the track-id field; each change redraws. */
export function buildFilters() {
  const cls = $("#filter-class");
  for (const c of ["vehicle", "human"]) {
    const box = el("input", { type: "checkbox", checked: true, "data-class": c });
    box.addEventListener("change", () => {
      if (box.checked) ui.filters.classes.add(c);
      else ui.filters.classes.delete(c);
      filtersChanged();
      drawLists(timeline.now());
    });
    cls.append(el("label", {}, box, " ", el("span", { class: "swatch", style: `background:${classColour(c)}` }), ` ${c}`));
  }
  const sens = $("#filter-sensor");
  const chosen = new Set(ui.sensors.map((s) => s.id));
  for (const s of ui.sensors) {
    const box = el("input", { type: "checkbox", checked: true, "data-sensor": s.id });
    box.addEventListener("change", () => {
      if (box.checked) chosen.add(s.id);
      else chosen.delete(s.id);
      ui.filters.sensors = chosen.size === ui.sensors.length ? null : new Set(chosen);
      filtersChanged();
      drawLists(timeline.now());
    });
    sens.append(el("label", {}, box, ` ${s.id}`));
  }
  const idField = $("#filter-track");
  idField.addEventListener("input", () => {
    const { ids, error } = parseTrackIds(idField.value);
    ui.filters.ids = ids;
    ui.filters.idError = error;
    idField.classList.toggle("invalid", !!error);
    idField.setAttribute("aria-invalid", String(!!error));
    $("#filter-track-error").textContent = error || "";
    filtersChanged();
    drawLists(timeline.now());
  });
}

