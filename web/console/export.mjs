// Export of the selection (tracks) and of the kept markers.
//
// Tracks are written by the server, `GET /api/tracks/export` (one writer per format, in
// core/io/track_io.py; `demtrack track -o` uses the same): the page asks for the selected
// track ids (and, when the trajectory window clips them, the window) and saves the bytes
// the server answers, unchanged. GeoJSON: RFC 7946 MultiLineString, one line per run
// between gaps, [lon, lat, h] with h ellipsoidal; CSV: longitude/latitude columns; GPX:
// <time> and <ele> per point; KML/KMZ: a gx:Track per run (absolute altitudes);
// GeoPackage: layers tracks and track_points with a spatial index. See docs/server.md.
//
// Markers live only in this page (no server store yet), so they are still written here:
// GeoJSON [lon, lat, h] (h above the ellipsoid), CSV, GPX and KML waypoints.

import { AuthError, token } from "./api.mjs";
import { download, escapeXml } from "./util.mjs";

// ------------------------------------------------------------------------- markers
export function markersGeoJSON(markers) {
  return {
    type: "FeatureCollection",
    features: markers.map((m) => ({
      type: "Feature",
      id: m.id,
      properties: { name: m.name, sensor: m.sensor, pixel: m.pixel, rule: m.rule, e_m: m.e_m, n_m: m.n_m, u_m: m.u_m, range_m: m.range_m, sigma_m: m.sigma_m },
      geometry: { type: "Point", coordinates: [m.lon_deg, m.lat_deg, m.h_m] },
    })),
  };
}

export function markersCSV(markers) {
  const rows = ["name,sensor,u_px,v_px,rule,e_m,n_m,u_m,lat_deg,lon_deg,h_m,range_m,sigma_m"];
  for (const m of markers) {
    rows.push([m.name, m.sensor, m.pixel[0], m.pixel[1], m.rule, m.e_m.toFixed(3), m.n_m.toFixed(3), m.u_m.toFixed(3),
      m.lat_deg.toFixed(9), m.lon_deg.toFixed(9), m.h_m.toFixed(3), m.range_m.toFixed(2), m.sigma_m.toFixed(2)].join(","));
  }
  return rows.join("\n") + "\n";
}

export function markersGPX(markers) {
  const out = ['<?xml version="1.0" encoding="UTF-8"?>',
    '<gpx version="1.1" creator="demtrack console" xmlns="http://www.topografix.com/GPX/1/1">'];
  for (const m of markers) {
    out.push(`<wpt lat="${m.lat_deg.toFixed(9)}" lon="${m.lon_deg.toFixed(9)}"><ele>${m.h_m.toFixed(3)}</ele><name>${escapeXml(m.name)}</name><desc>${escapeXml(`${m.sensor} pixel ${m.pixel[0]},${m.pixel[1]} rule ${m.rule}`)}</desc></wpt>`);
  }
  out.push("</gpx>");
  return out.join("\n") + "\n";
}

export function markersKML(markers) {
  const out = ['<?xml version="1.0" encoding="UTF-8"?>',
    '<kml xmlns="http://www.opengis.net/kml/2.2"><Document><name>demtrack markers</name>'];
  for (const m of markers) {
    out.push(`<Placemark><name>${escapeXml(m.name)}</name><Point><altitudeMode>absolute</altitudeMode><coordinates>${m.lon_deg.toFixed(9)},${m.lat_deg.toFixed(9)},${m.h_m.toFixed(3)}</coordinates></Point></Placemark>`);
  }
  out.push("</Document></kml>");
  return out.join("\n") + "\n";
}

/** Track formats the server writes: value -> file extension. */
export const FORMATS = {
  geojson: { ext: "geojson" },
  csv: { ext: "csv" },
  gpx: { ext: "gpx" },
  kml: { ext: "kml" },
  kmz: { ext: "kmz" },
  gpkg: { ext: "gpkg" },
};
/** Formats the page can write markers in. */
export const MARKER_FORMATS = ["geojson", "csv", "gpx", "kml"];

/** The export URL of `tracks` (page track objects, possibly clipped to a window). */
export function tracksExportURL(format, tracks, { clipped = false } = {}) {
  if (!FORMATS[format]) throw new Error(`unknown format ${format}`);
  const q = new URLSearchParams({ format });
  for (const t of tracks) q.append("track", String(t.id));
  if (clipped) {
    // The server clips each track to [t_from, t_to]: the span of the clipped points gives
    // every track the same points the page holds for it.
    const ts = tracks.flatMap((t) => (t.points.length ? [t.points[0].t_s, t.points[t.points.length - 1].t_s] : []));
    if (ts.length) {
      q.set("t_from", String(Math.min(...ts)));
      q.set("t_to", String(Math.max(...ts)));
    }
  }
  return `/api/tracks/export?${q}`;
}

/** The server's file for the tracks: {blob, name}. */
export async function fetchTracksExport(format, tracks, opts = {}) {
  const h = {};
  const t = token();
  if (t) h.Authorization = `Bearer ${t}`;
  const url = tracksExportURL(format, tracks, opts);
  const resp = await fetch(url, { headers: h });
  if (resp.status === 401) throw new AuthError("operator token required or wrong");
  if (!resp.ok) {
    let detail = resp.statusText;
    try {
      detail = (await resp.json()).detail || detail;
    } catch (_) {
      /* not JSON */
    }
    throw new Error(`export: ${resp.status} ${detail}`);
  }
  return { blob: await resp.blob(), name: `demtrack-tracks.${FORMATS[format].ext}` };
}

/** Saves the tracks, as the server writes them, as `demtrack-tracks.<ext>`. */
export async function downloadTracks(format, tracks) {
  const clipped = !!document.querySelector("#syn-on")?.checked;
  const button = document.querySelector("#export-tracks");
  if (button) button.dataset.state = "busy";
  try {
    const { blob, name } = await fetchTracksExport(format, tracks, { clipped });
    download(name, blob.type || "application/octet-stream", blob);
    if (button) button.dataset.state = "done";
  } catch (err) {
    if (button) {
      button.dataset.state = "error";
      button.title = String(err.message || err);
    }
    console.warn(`track export failed: ${err.message || err}`);
  }
}

export function renderMarkers(format, markers) {
  if (format === "geojson") return JSON.stringify(markersGeoJSON(markers), null, 1);
  if (format === "csv") return markersCSV(markers);
  if (format === "gpx") return markersGPX(markers);
  if (format === "kml") return markersKML(markers);
  throw new Error(`markers cannot be written as ${format} in the page (use GeoJSON, CSV, GPX or KML)`);
}

const MARKER_MIME = {
  geojson: "application/geo+json",
  csv: "text/csv",
  gpx: "application/gpx+xml",
  kml: "application/vnd.google-earth.kml+xml",
};

/** Saves the markers as a file in the format (`demtrack-markers.<ext>`); GeoJSON when the
 * chosen format is one only the server writes (KMZ, GeoPackage). */
export function downloadMarkers(format, markers) {
  const f = MARKER_FORMATS.includes(format) ? format : "geojson";
  download(`demtrack-markers.${f}`, MARKER_MIME[f], renderMarkers(f, markers));
}
