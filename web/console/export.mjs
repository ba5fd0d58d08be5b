// Client-side export of the selection (tracks) and of the kept markers.
//
// GeoJSON follows RFC 7946: WGS84 positions as [lon, lat, h] (h above the ellipsoid).
// CSV carries both the site frame (e/n/u, m) and WGS84. GPX and KML are WGS84 lon/lat
// with heights above the ellipsoid. Times are session seconds (t_s): no wall-clock epoch
// is known to the console, so GPX <time> is left out and t_s goes into each point's <desc>.

import { download, escapeXml } from "./util.mjs";

function trackProps(t) {
  const pts = t.points;
  return {
    track_id: t.id,
    class: t.cls,
    sensors: t.sensors,
    t_start_s: pts.length ? pts[0].t_s : null,
    t_end_s: pts.length ? pts[pts.length - 1].t_s : null,
    n_points: pts.length,
    gaps_s: t.gaps,
    times_s: pts.map((p) => p.t_s),
  };
}

export function tracksGeoJSON(tracks) {
  return {
    type: "FeatureCollection",
    features: tracks
      .filter((t) => t.points.length)
      .map((t) => ({
        type: "Feature",
        id: t.id,
        properties: trackProps(t),
        geometry:
          t.points.length === 1
            ? { type: "Point", coordinates: [t.points[0].lon_deg, t.points[0].lat_deg, t.points[0].h_m] }
            : { type: "LineString", coordinates: t.points.map((p) => [p.lon_deg, p.lat_deg, p.h_m]) },
      })),
  };
}

export function tracksCSV(tracks) {
  const rows = ["track_id,class,t_s,e_m,n_m,u_m,lat_deg,lon_deg,h_m,sensors"];
  for (const t of tracks) {
    for (const p of t.points) {
      rows.push(
        [t.id, t.cls, p.t_s, p.e_m.toFixed(3), p.n_m.toFixed(3), p.u_m.toFixed(3),
          p.lat_deg.toFixed(9), p.lon_deg.toFixed(9), p.h_m.toFixed(3), (p.sensors || []).join(";")].join(","),
      );
    }
  }
  return rows.join("\n") + "\n";
}

export function tracksGPX(tracks) {
  const out = ['<?xml version="1.0" encoding="UTF-8"?>',
    '<gpx version="1.1" creator="demtrack console" xmlns="http://www.topografix.com/GPX/1/1">'];
  for (const t of tracks) {
    out.push(`<trk><name>track ${t.id} (${escapeXml(t.cls)})</name><trkseg>`);
    for (const p of t.points) {
      out.push(`<trkpt lat="${p.lat_deg.toFixed(9)}" lon="${p.lon_deg.toFixed(9)}"><ele>${p.h_m.toFixed(3)}</ele><desc>t_s=${p.t_s}</desc></trkpt>`);
    }
    out.push("</trkseg></trk>");
  }
  out.push("</gpx>");
  return out.join("\n") + "\n";
}

export function tracksKML(tracks) {
  const out = ['<?xml version="1.0" encoding="UTF-8"?>',
    '<kml xmlns="http://www.opengis.net/kml/2.2"><Document><name>demtrack tracks</name>'];
  for (const t of tracks) {
    const coords = t.points.map((p) => `${p.lon_deg.toFixed(9)},${p.lat_deg.toFixed(9)},${p.h_m.toFixed(3)}`).join(" ");
    out.push(`<Placemark><name>track ${t.id}</name><description>${escapeXml(t.cls)}; t_s ${t.points.length ? t.points[0].t_s : ""}–${t.points.length ? t.points[t.points.length - 1].t_s : ""}</description>`);
    out.push(`<LineString><altitudeMode>absolute</altitudeMode><coordinates>${coords}</coordinates></LineString></Placemark>`);
  }
  out.push("</Document></kml>");
  return out.join("\n") + "\n";
}

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

export const FORMATS = {
  geojson: { ext: "geojson", mime: "application/geo+json" },
  csv: { ext: "csv", mime: "text/csv" },
  gpx: { ext: "gpx", mime: "application/gpx+xml" },
  kml: { ext: "kml", mime: "application/vnd.google-earth.kml+xml" },
};

export function renderTracks(format, tracks) {
  if (format === "geojson") return JSON.stringify(tracksGeoJSON(tracks), null, 1);
  if (format === "csv") return tracksCSV(tracks);
  if (format === "gpx") return tracksGPX(tracks);
  if (format === "kml") return tracksKML(tracks);
  throw new Error(`unknown format ${format}`);
}

export function renderMarkers(format, markers) {
  if (format === "geojson") return JSON.stringify(markersGeoJSON(markers), null, 1);
  if (format === "csv") return markersCSV(markers);
  if (format === "gpx") return markersGPX(markers);
  if (format === "kml") return markersKML(markers);
  throw new Error(`unknown format ${format}`);
}

/** Saves the tracks as a file in the format (`demtrack-tracks.<ext>`). */
export function downloadTracks(format, tracks) {
  const f = FORMATS[format];
  download(`demtrack-tracks.${f.ext}`, f.mime, renderTracks(format, tracks));
}

/** Saves the markers as a file in the format (`demtrack-markers.<ext>`). */
export function downloadMarkers(format, markers) {
  const f = FORMATS[format];
  download(`demtrack-markers.${f.ext}`, f.mime, renderMarkers(format, markers));
}
