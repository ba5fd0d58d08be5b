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
// Markers are stored by the server and written by it too, `GET /api/markers/export`:
// GeoJSON [lon, lat, h] (h above the ellipsoid), CSV, GPX waypoints and KML placemarks
// (<ele> / absolute altitudes above the geoid where the site has a geoid model).

import { AuthError, token } from "./api.mjs";
import { download } from "./util.mjs";

/** Track formats the server writes: value -> file extension. */
export const FORMATS = {
  geojson: { ext: "geojson" },
  csv: { ext: "csv" },
  gpx: { ext: "gpx" },
  kml: { ext: "kml" },
  kmz: { ext: "kmz" },
  gpkg: { ext: "gpkg" },
};
/** Formats the server writes markers in (GET /api/markers/export). */
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

/** The server's file at `url` (an export endpoint): {blob, name}. */
async function fetchExport(url, name) {
  const h = {};
  const t = token();
  if (t) h.Authorization = `Bearer ${t}`;
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
  return { blob: await resp.blob(), name };
}

/** The server's file for the tracks: {blob, name}. */
export function fetchTracksExport(format, tracks, opts = {}) {
  return fetchExport(tracksExportURL(format, tracks, opts), `demtrack-tracks.${FORMATS[format].ext}`);
}

/** Saves the server's file for `what` ("tracks" or "markers"), marking the button's state. */
async function save(button, fetching) {
  if (button) button.dataset.state = "busy";
  try {
    const { blob, name } = await fetching();
    download(name, blob.type || "application/octet-stream", blob);
    if (button) button.dataset.state = "done";
  } catch (err) {
    if (button) {
      button.dataset.state = "error";
      button.title = String(err.message || err);
    }
    console.warn(`export failed: ${err.message || err}`);
  }
}

/** Saves the tracks, as the server writes them, as `demtrack-tracks.<ext>`. */
export function downloadTracks(format, tracks) {
  const clipped = !!document.querySelector("#syn-on")?.checked;
  return save(document.querySelector("#export-tracks"), () => fetchTracksExport(format, tracks, { clipped }));
}

/** Saves every stored marker as the server writes them (`demtrack-markers.<ext>`); GeoJSON
 * when the chosen format is a track-only one (KMZ, GeoPackage). */
export function downloadMarkers(format) {
  const f = MARKER_FORMATS.includes(format) ? format : "geojson";
  return save(document.querySelector("#export-markers"),
    () => fetchExport(`/api/markers/export?format=${f}`, `demtrack-markers.${f}`));
}
