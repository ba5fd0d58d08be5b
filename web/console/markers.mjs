// Kept markers: geolocated points the operator keeps, on the map and in the sidebar's list
// (a click centres the map on one; ✕ removes it), exported with "Export markers".

import { ui } from "./state.mjs";
import { $, el, fmt } from "./util.mjs";

/** Keeps the chosen hit of the geolocation shown as the next marker (M1, M2, ...). */
export function keepMarker() {
  const res = ui.geo?.result;
  const h = res?.selected?.[0];
  if (!h) return;
  const n = ui.markers.length ? ui.markers[ui.markers.length - 1].id + 1 : 1;
  ui.markers.push({ id: n, name: `M${n}`, sensor: res.sensor, pixel: res.pixel, rule: res.rule, ...h });
  drawMarkers();
}

function drawMarkers() {
  ui.map.drawMarkers(ui.markers);
  $("#export-markers").disabled = !ui.markers.length;
  $("#marker-list").replaceChildren(...ui.markers.map((m) => el("div", {
    title: `${m.sensor} pixel ${m.pixel.join(", ")}, rule ${m.rule}`,
    onclick: () => ui.map.centreOn(m.e_m, m.n_m),
  },
  el("b", { text: m.name }),
  el("span", { class: "mono", text: `E ${fmt(m.e_m, 1)} N ${fmt(m.n_m, 1)}` }),
  el("span", { class: "grow" }),
  el("button", {
    title: "remove marker",
    onclick: (ev) => {
      ev.stopPropagation();
      ui.markers = ui.markers.filter((x) => x !== m);
      drawMarkers();
    },
  }, "✕"))));
}

