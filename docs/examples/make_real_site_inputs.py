"""Raw inputs for the worked real-site example of ``docs/site-format.md``, with the answer.

Writes, into one folder, what a user brings to build a site near Bushy Run (PA), each in
its own CRS, all sampled from one synthetic world whose truth is known:

==============================  ===========================================================
``lidar_utm17.laz``             a lidar tile, WGS 84 / UTM 17N (EPSG:32617), NAVD88 heights
                                (m): ground (class 2, 3 pts/m^2, 3 cm noise), trees (class 5)
                                and roofs (class 6)
``dem_utm17_1m.tif``            a 1 m DEM tile in UTM 17N, NAVD88 (m), nodata -9999 over a
                                data void
``dem_pa_south_ftus.tif``       the next tile east, NAD83 / Pennsylvania South (ftUS)
                                (EPSG:2272), 3 ft cells, NAVD88 heights in US survey feet
``ned_1arcsec.tif``             a coarse 1-arc-second DEM in NAD83 degrees (EPSG:4269),
                                NAVD88 (m), 0.5 m noise: the fallback for gaps
``ortho_pa_south.tif``          an 8-bit RGB orthophoto in EPSG:2272, 3 ft pixels
``roads_pa_south.gpkg``         road centre lines, a GeoPackage layer in EPSG:2272
``cam1_intrinsics.json``        the camera's lab calibration (OpenCV model)
``cam1_survey.json``            the camera's survey: RTK position in UTM 17N (NAVD88) and a
                                grid bearing and inclinometer tilt, both a little wrong
``cam1_gcps.csv``               12 ground control points (pixel <-> UTM 17N, NAVD88), 0.4 px
                                picking noise and one blunder
``truth.json``                  the answer key: the true camera pose, and a pixel with the
                                ground point it sees
==============================  ===========================================================

The truth is computed without demtrack (pyproj, numpy): the terrain is an analytic
surface of UTM coordinates, and pixels come from a pinhole + OpenCV radial model posed in
the camera's own east-north-up frame through ECEF, so the example's final geolocation is
checked against an independent answer. The geoid undulation is taken as a constant
-33.5 m over the site (``h = H + N``), the value the example states.

Run ``python docs/examples/make_real_site_inputs.py OUT_DIR``. Deterministic (fixed seed).
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import struct
import sys
from pathlib import Path

import laspy
import numpy as np
import rasterio
import shapely
from affine import Affine
from pyproj import CRS, Geod, Transformer

__all__ = ["GEOID_UNDULATION_M", "terrain_h_m", "make_real_site_inputs", "main"]

UTM = "EPSG:32617"
STATE_PLANE = "EPSG:2272"  # NAD83 / Pennsylvania South (ftUS)
NAD83 = "EPSG:4269"
FT_US = 1200.0 / 3937.0  # metres per US survey foot
#: The site's geoid undulation N (m): NAVD88 height H -> WGS84 ellipsoidal h = H + N.
GEOID_UNDULATION_M = -33.5
#: UTM 17N origin of the world's offsets (dx, dy), m; near Bushy Run, PA.
X0, Y0 = 617000.0, 4468100.0

_TO_UTM = Transformer.from_crs("EPSG:4326", UTM, always_xy=True)
_FROM_UTM = Transformer.from_crs(UTM, "EPSG:4326", always_xy=True)
_UTM_TO_SP = Transformer.from_crs(UTM, STATE_PLANE, always_xy=True)
_SP_TO_UTM = Transformer.from_crs(STATE_PLANE, UTM, always_xy=True)
_NAD83_TO_UTM = Transformer.from_crs(NAD83, UTM, always_xy=True)
_LLH_TO_ECEF = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
_GEOD = Geod(ellps="WGS84")

# The world, in UTM offsets (m) from (X0, Y0).
_BUILDINGS = [  # (dx0, dy0, dx1, dy1, height m)
    (-95.0, -250.0, -70.0, -232.0, 7.5),
    (30.0, -150.0, 52.0, -120.0, 9.0),
    (-120.0, -60.0, -98.0, -38.0, 6.0),
]
_ROADS = [  # name, width (m), vertices (dx, dy)
    ("Bushy Run Road", 7.0, [(-450.0, -330.0), (-150.0, -230.0), (20.0, -90.0),
                             (160.0, 80.0), (450.0, 260.0)]),
    ("Museum Drive", 5.0, [(20.0, -90.0), (-60.0, 10.0), (-110.0, 150.0), (-160.0, 450.0)]),
]  # fmt: skip
_VOID = (-200.0, 150.0, 35.0)  # centre dx, dy and radius (m) of the 1 m tile's data void
_LIDAR_BOX = (-150.0, -300.0, 150.0, 0.0)
_CAMERA_DXY = (-40.0, -200.0)
_CAMERA_MAST_M = 20.0

# The camera as it really is (true azimuth at the camera, tilt, roll), and as surveyed.
_INTRINSICS = {"fx": 1450.0, "fy": 1450.0, "cx": 962.7, "cy": 537.4, "width": 1920,
               "height": 1080, "k1": -0.06, "k2": 0.01, "p1": 0.0, "p2": 0.0,
               "k3": 0.0}  # fmt: skip
_TRUE_AZ_DEG, _TRUE_TILT_DEG, _TRUE_ROLL_DEG = 24.0, -8.0, 0.35
_SURVEY_GRID_AZ_ERROR_DEG = -1.7  # a bearing read off the map, 1.7 deg off
_SURVEY_TILT_DEG = -7.5  # an inclinometer reading, 0.5 deg off
# GCPs as (bearing off the optical axis deg, range m); one of them is mis-picked.
_GCP_SIGHTS = [(-25.0, 52.0), (-12.0, 70.0), (5.0, 48.0), (18.0, 60.0), (28.0, 90.0),
               (-20.0, 140.0), (0.0, 120.0), (14.0, 180.0), (-8.0, 260.0), (22.0, 320.0),
               (-15.0, 420.0), (6.0, 520.0)]  # fmt: skip
_BLUNDER = (7, 28.0, -6.0)  # index, du, dv (px)
_PIXEL_NOISE_PX = 0.4
# The pixel the example geolocates: a point on Bushy Run Road.
_TARGET_ROAD, _TARGET_FRACTION = 0, 0.47


def terrain_h_m(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """True ground height (m, NAVD88) at UTM offsets ``dx, dy`` (m) from (X0, Y0)."""
    dx, dy = np.asarray(dx, np.float64), np.asarray(dy, np.float64)
    hill = 7.0 * np.exp(-((dx - 180.0) ** 2 + (dy - 260.0) ** 2) / (2.0 * 130.0**2))
    waves = 1.8 * np.sin(dx / 85.0 + 0.3) * np.cos(dy / 120.0)
    return 318.0 + 0.035 * dx + 0.025 * dy + hill + waves


# --------------------------------------------------------------------------- camera model


def _enu_basis(lat_deg: float, lon_deg: float) -> np.ndarray:
    """Rows: east, north, up unit vectors (ECEF) at a WGS84 position."""
    p, la = np.radians(lat_deg), np.radians(lon_deg)
    return np.array(
        [
            [-np.sin(la), np.cos(la), 0.0],
            [-np.sin(p) * np.cos(la), -np.sin(p) * np.sin(la), np.cos(p)],
            [np.cos(p) * np.cos(la), np.cos(p) * np.sin(la), np.sin(p)],
        ]
    )


def _r_enu_cam(az_deg: float, tilt_deg: float, roll_deg: float) -> np.ndarray:
    """Columns: camera x (right), y (down), z (forward) in the camera's own ENU."""
    az, tilt, roll = np.radians([az_deg, tilt_deg, roll_deg])
    fwd = np.array([np.sin(az) * np.cos(tilt), np.cos(az) * np.cos(tilt), np.sin(tilt)])
    right0 = np.array([np.cos(az), -np.sin(az), 0.0])
    down0 = np.cross(fwd, right0)
    right = np.cos(roll) * right0 + np.sin(roll) * down0
    down = np.cos(roll) * down0 - np.sin(roll) * right0
    return np.column_stack([right, down, fwd])


def _utm_to_llh(x: np.ndarray, y: np.ndarray, h_ortho: np.ndarray) -> tuple[np.ndarray, ...]:
    lon, lat = _FROM_UTM.transform(x, y)
    return np.asarray(lat), np.asarray(lon), np.asarray(h_ortho) + GEOID_UNDULATION_M


def _project(cam: dict, x: np.ndarray, y: np.ndarray, h_ortho: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` of UTM points with NAVD88 heights, seen by the true camera."""
    lat_c, lon_c, h_c = _utm_to_llh(cam["x"], cam["y"], cam["z"])
    c_ecef = np.array(_LLH_TO_ECEF.transform(lon_c, lat_c, h_c))
    lat, lon, h = _utm_to_llh(x, y, h_ortho)
    p_ecef = np.array(_LLH_TO_ECEF.transform(lon, lat, h)).reshape(3, -1)
    p_enu = _enu_basis(float(lat_c), float(lon_c)) @ (p_ecef - c_ecef[:, None])
    p_cam = _r_enu_cam(cam["az_true_deg"], cam["tilt_deg"], cam["roll_deg"]).T @ p_enu
    if np.any(p_cam[2] <= 0):
        raise ValueError("a point is behind the camera")
    xn, yn = p_cam[0] / p_cam[2], p_cam[1] / p_cam[2]
    k = _INTRINSICS
    r2 = xn * xn + yn * yn
    g = 1.0 + r2 * (k["k1"] + r2 * k["k2"])
    return np.column_stack([k["fx"] * xn * g + k["cx"], k["fy"] * yn * g + k["cy"]])


def _grid_azimuth_deg(x: float, y: float, az_true_deg: float) -> float:
    """Grid bearing (UTM) of a true azimuth at a UTM point, by a 200 m geodesic."""
    lon, lat = _FROM_UTM.transform(x, y)
    lon2, lat2, _ = _GEOD.fwd(lon, lat, az_true_deg, 200.0)
    x2, y2 = _TO_UTM.transform(lon2, lat2)
    return float(np.degrees(np.arctan2(x2 - x, y2 - y)))


def _ground_point(cam: dict, bearing_deg: float, range_m: float) -> tuple[float, float, float]:
    lon, lat = _FROM_UTM.transform(cam["x"], cam["y"])
    lon2, lat2, _ = _GEOD.fwd(lon, lat, cam["az_true_deg"] + bearing_deg, range_m)
    x, y = _TO_UTM.transform(lon2, lat2)
    return float(x), float(y), float(terrain_h_m(x - X0, y - Y0))


# --------------------------------------------------------------------------- writers


def _write_tif(
    path: Path, data: np.ndarray, transform: Affine, crs: str, unit: str = "metre", **extra
) -> None:
    bands = data[None] if data.ndim == 2 else data
    profile = dict(driver="GTiff", height=bands.shape[1], width=bands.shape[2],
                   count=bands.shape[0], dtype=bands.dtype.name, transform=transform,
                   crs=crs, compress="deflate", **extra)  # fmt: skip
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(bands)
        if bands.dtype.kind == "f":
            dst.set_band_unit(1, unit)


def _utm_grid(transform: Affine, shape: tuple[int, int], to_utm: Transformer | None):
    """UTM offsets (dx, dy) of a raster's cell centres."""
    cols, rows = np.meshgrid(np.arange(shape[1]) + 0.5, np.arange(shape[0]) + 0.5)
    x, y = transform @ (cols, rows)
    if to_utm is not None:
        x, y = to_utm.transform(x, y)
    return np.asarray(x) - X0, np.asarray(y) - Y0


def _write_dem_tiles(out: Path, rng: np.random.Generator) -> None:
    # Tile A: UTM, 1 m, dx -300..40, dy -300..300, a data void.
    t = Affine(1.0, 0.0, X0 - 300.0, 0.0, -1.0, Y0 + 300.0)
    dx, dy = _utm_grid(t, (600, 340), None)
    z = terrain_h_m(dx, dy).astype(np.float32)
    cx, cy, r = _VOID
    z[np.hypot(dx - cx, dy - cy) < r] = -9999.0
    _write_tif(out / "dem_utm17_1m.tif", z, t, UTM, nodata=-9999.0)
    # Tile B: the state-plane tile east of it, 3 ftUS cells, heights in ftUS.
    xs, ys = _UTM_TO_SP.transform([X0 + 50.0, X0 + 300.0], [Y0 - 300.0, Y0 + 300.0])
    t = Affine(3.0, 0.0, float(np.floor(xs[0])), 0.0, -3.0, float(np.ceil(ys[1])))
    shape = (int((ys[1] - ys[0]) / 3.0), int((xs[1] - xs[0]) / 3.0))
    dx, dy = _utm_grid(t, shape, _SP_TO_UTM)
    z_ft = (terrain_h_m(dx, dy) / FT_US).astype(np.float32)
    _write_tif(out / "dem_pa_south_ftus.tif", z_ft, t, STATE_PLANE, nodata=-9999.0,
               unit="US survey foot")  # fmt: skip
    # Coarse: 1 arc-second NAD83 over the site and a margin, 0.5 m noise.
    s = 1.0 / 3600.0
    lon_w, lat_s = _FROM_UTM.transform(X0 - 500.0, Y0 - 500.0)
    t = Affine(s, 0.0, np.floor(lon_w / s) * s, 0.0, -s, np.ceil((lat_s + 0.0091) / s) * s)
    dx, dy = _utm_grid(t, (33, 43), _NAD83_TO_UTM)
    z = terrain_h_m(dx, dy) + rng.normal(0.0, 0.5, dx.shape)
    _write_tif(out / "ned_1arcsec.tif", z.astype(np.float32), t, NAD83, nodata=-9999.0)


def _trees(rng: np.random.Generator, avoid: np.ndarray) -> np.ndarray:
    """Tree crowns (dx, dy, radius, height) off the roads, roofs and ``avoid`` points."""
    roads = shapely.MultiLineString([r[2] for r in _ROADS])
    roofs = shapely.MultiPolygon([shapely.box(*b[:4]) for b in _BUILDINGS])
    keep = []
    while len(keep) < 40:
        dx, dy = rng.uniform(-295, 295), rng.uniform(-295, 295)
        rad, h = rng.uniform(3.0, 5.5), rng.uniform(9.0, 17.0)
        p = shapely.Point(dx, dy)
        if p.distance(roads) < rad + 6 or p.distance(roofs) < rad + 3:
            continue
        if np.min(np.hypot(avoid[:, 0] - dx, avoid[:, 1] - dy)) < rad + 6:
            continue
        keep.append((dx, dy, rad, h))
    return np.array(keep)


def _write_lidar(out: Path, rng: np.random.Generator, trees: np.ndarray) -> None:
    x0, y0, x1, y1 = _LIDAR_BOX
    area = (x1 - x0) * (y1 - y0)
    n = rng.poisson(3.0 * area)
    gx, gy = rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)
    on_roof = np.zeros(n, bool)
    for b in _BUILDINGS:
        on_roof |= (gx >= b[0]) & (gx <= b[2]) & (gy >= b[1]) & (gy <= b[3])
    gx, gy = gx[~on_roof], gy[~on_roof]
    under = np.zeros(gx.size, bool)
    parts = []
    for tx, ty, rad, h in trees:
        if not (x0 - rad < tx < x1 + rad and y0 - rad < ty < y1 + rad):
            continue
        under |= np.hypot(gx - tx, gy - ty) < rad
        m = rng.poisson(4.0 * np.pi * rad**2)
        d, a = rad * np.sqrt(rng.uniform(0, 1, m)), rng.uniform(0, 2 * np.pi, m)
        cx, cy = tx + d * np.cos(a), ty + d * np.sin(a)
        cz = terrain_h_m(tx, ty) + h * (1.0 - 0.45 * (d / rad) ** 2) + rng.normal(0, 0.3, m)
        inside = (cx > x0) & (cx < x1) & (cy > y0) & (cy < y1)
        parts.append((cx[inside], cy[inside], cz[inside], 5, 1, 2))
    gz = terrain_h_m(gx, gy) + rng.normal(0.0, 0.03, gx.size)
    ret = np.where(under, 2, 1)
    parts.append((gx, gy, gz, 2, ret, ret))
    for bx0, by0, bx1, by1, h in _BUILDINGS:
        m = rng.poisson(3.0 * (bx1 - bx0) * (by1 - by0))
        rx, ry = rng.uniform(bx0, bx1, m), rng.uniform(by0, by1, m)
        rz = terrain_h_m((bx0 + bx1) / 2, (by0 + by1) / 2) + h + rng.normal(0, 0.03, m)
        parts.append((rx, ry, rz, 6, 1, 1))
    xs, ys, zs, cls, rn, nr = [], [], [], [], [], []
    for px, py, pz, c, r, nret in parts:
        xs.append(px + X0)
        ys.append(py + Y0)
        zs.append(pz)
        cls.append(np.broadcast_to(c, px.shape))
        rn.append(np.broadcast_to(r, px.shape))
        nr.append(np.broadcast_to(nret, px.shape))
    order = rng.permutation(sum(a.size for a in xs))
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = [X0, Y0, 0.0]
    header.scales = [0.001, 0.001, 0.001]
    header.add_crs(CRS.from_user_input(UTM))
    las = laspy.LasData(header)
    las.x = np.concatenate(xs)[order]
    las.y = np.concatenate(ys)[order]
    las.z = np.concatenate(zs)[order]
    las.classification = np.concatenate(cls)[order].astype(np.uint8)
    las.return_number = np.concatenate(rn)[order].astype(np.uint8)
    las.number_of_returns = np.concatenate(nr)[order].astype(np.uint8)
    las.write(out / "lidar_utm17.laz")


def _segment_distance(px: np.ndarray, py: np.ndarray, xy: list) -> np.ndarray:
    best = np.full(px.shape, np.inf)
    for (ax, ay), (bx, by) in zip(xy[:-1], xy[1:], strict=True):
        vx, vy = bx - ax, by - ay
        t = np.clip(((px - ax) * vx + (py - ay) * vy) / (vx * vx + vy * vy), 0.0, 1.0)
        best = np.minimum(best, np.hypot(px - ax - t * vx, py - ay - t * vy))
    return best


def _write_ortho(out: Path, rng: np.random.Generator, trees: np.ndarray) -> None:
    xs, ys = _UTM_TO_SP.transform([X0 - 310.0, X0 + 310.0], [Y0 - 310.0, Y0 + 310.0])
    t = Affine(3.0, 0.0, float(np.floor(xs[0])), 0.0, -3.0, float(np.ceil(ys[1])))
    shape = (int((ys[1] - ys[0]) / 3.0), int((xs[1] - xs[0]) / 3.0))
    dx, dy = _utm_grid(t, shape, _SP_TO_UTM)
    shade = 12.0 * np.sin(dx / 37.0) * np.cos(dy / 53.0) + rng.normal(0.0, 6.0, dx.shape)
    rgb = np.stack([78 + shade, 118 + shade, 58 + 0.5 * shade])  # grass
    cx, cy, r = _VOID
    rgb[:, np.hypot(dx - cx, dy - cy) < r * 0.8] = np.array([48, 74, 96])[:, None]  # pond
    for tx, ty, rad, _h in trees:
        rgb[:, np.hypot(dx - tx, dy - ty) < rad] = np.array([38, 66, 34])[:, None]
    for bx0, by0, bx1, by1, _h in _BUILDINGS:
        roof = (dx >= bx0) & (dx <= bx1) & (dy >= by0) & (dy <= by1)
        rgb[:, roof] = np.array([150, 72, 60])[:, None]
    for _name, width, xy in _ROADS:
        rgb[:, _segment_distance(dx, dy, xy) < width / 2] = np.array([92, 92, 98])[:, None]
    rgb = np.clip(rgb, 0, 255).astype(np.uint8)
    _write_tif(out / "ortho_pa_south.tif", rgb, t, STATE_PLANE, photometric="RGB")


def _gpkg_blob(geom: shapely.Geometry, srs_id: int) -> bytes:
    # GeoPackage geometry: 'GP', version 0, flags (little endian, [minx maxx miny maxy]
    # envelope), srs_id, envelope, then ISO WKB.
    minx, miny, maxx, maxy = geom.bounds
    header = b"GP" + bytes([0, 0b00000011]) + struct.pack("<i", srs_id)
    return header + struct.pack("<4d", minx, maxx, miny, maxy) + shapely.to_wkb(geom)


def _write_roads(out: Path) -> None:
    path = out / "roads_pa_south.gpkg"
    path.unlink(missing_ok=True)
    con = sqlite3.connect(path)
    con.executescript(
        """
        CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT, srs_id INTEGER PRIMARY KEY,
            organization TEXT, organization_coordsys_id INTEGER, definition TEXT,
            description TEXT);
        CREATE TABLE gpkg_geometry_columns (table_name TEXT, column_name TEXT,
            geometry_type_name TEXT, srs_id INTEGER, z INTEGER, m INTEGER);
        CREATE TABLE roads (fid INTEGER PRIMARY KEY, geom BLOB, name TEXT, width_m REAL);
        """
    )
    con.execute(
        "INSERT INTO gpkg_spatial_ref_sys VALUES (?, 2272, 'EPSG', 2272, ?, '')",
        ("NAD83 / Pennsylvania South (ftUS)", CRS.from_user_input(STATE_PLANE).to_wkt()),
    )
    con.execute("INSERT INTO gpkg_geometry_columns VALUES ('roads', 'geom', 'LINESTRING', "
                "2272, 0, 0)")  # fmt: skip
    for k, (name, width, xy) in enumerate(_ROADS):
        dense = shapely.segmentize(shapely.LineString(xy), 20.0)
        d = np.asarray(dense.coords)
        x, y = _UTM_TO_SP.transform(d[:, 0] + X0, d[:, 1] + Y0)
        blob = _gpkg_blob(shapely.LineString(np.column_stack([x, y])), 2272)
        con.execute("INSERT INTO roads VALUES (?, ?, ?, ?)", (k + 1, blob, name, width))
    con.commit()
    con.close()


# --------------------------------------------------------------------------- main


def make_real_site_inputs(out: str | Path, *, seed: int = 0) -> dict:
    """Write the example's raw inputs into ``out`` and return the answer key.

    Returns
    -------
    dict
        What ``truth.json`` holds: ``camera`` (true UTM position, NAVD88 height, true
        azimuth, tilt, roll), ``survey`` (what ``cam1_survey.json`` says) and ``target``
        (``pixel`` [u, v] and the ground point it sees: UTM ``x, y``, NAVD88 ``H_m``,
        WGS84 ``lat_deg, lon_deg`` and ellipsoidal ``h_m``).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    cx, cy = X0 + _CAMERA_DXY[0], Y0 + _CAMERA_DXY[1]
    cam = {
        "x": cx,
        "y": cy,
        "z": round(float(terrain_h_m(*_CAMERA_DXY)) + _CAMERA_MAST_M, 2),
        "crs": UTM,
        "vertical": "NAVD88 (orthometric)",
        "az_true_deg": _TRUE_AZ_DEG,
        "tilt_deg": _TRUE_TILT_DEG,
        "roll_deg": _TRUE_ROLL_DEG,
    }
    grid_az = _grid_azimuth_deg(cx, cy, _TRUE_AZ_DEG)
    survey = {
        "position": [cam["x"], cam["y"], cam["z"]],
        "crs": UTM,
        "vertical_datum": "orthometric",
        "grid_azimuth_deg": round(grid_az + _SURVEY_GRID_AZ_ERROR_DEG, 1),
        "tilt_deg": _SURVEY_TILT_DEG,
    }
    # GCPs: surveyed ground points, their pixels picked with noise, one mis-picked.
    pts = np.array([_ground_point(cam, b, r) for b, r in _GCP_SIGHTS])
    uv = _project(cam, pts[:, 0], pts[:, 1], pts[:, 2])
    uv_obs = uv + rng.normal(0.0, _PIXEL_NOISE_PX, uv.shape)
    k, du, dv = _BLUNDER
    uv_obs[k] += (du, dv)
    k_in = _INTRINSICS
    if not np.all((uv >= 0) & (uv <= (k_in["width"] - 1, k_in["height"] - 1))):
        raise ValueError(f"a GCP falls outside the image: {uv.round(1).tolist()}")
    lines = ["# crs: EPSG:32617", "# vertical: orthometric", "name,u,v,x,y,z"]
    for i, ((u, v), (x, y, z)) in enumerate(zip(uv_obs, pts, strict=True)):
        lines.append(f"gcp{i + 1:02d},{u:.1f},{v:.1f},{x:.3f},{y:.3f},{z:.3f}")
    (out / "cam1_gcps.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    # The target: a point on the road, and the pixel that sees it (rounded to 0.1 px).
    road = shapely.LineString(_ROADS[_TARGET_ROAD][2])
    p = road.interpolate(_TARGET_FRACTION, normalized=True)
    tx, ty = p.x + X0, p.y + Y0
    t_h = float(terrain_h_m(p.x, p.y))
    t_uv = _project(cam, np.array([tx]), np.array([ty]), np.array([t_h]))[0]
    lon, lat = _FROM_UTM.transform(tx, ty)
    target = {
        "pixel": [round(float(t_uv[0]), 1), round(float(t_uv[1]), 1)],
        "pixel_exact": [float(t_uv[0]), float(t_uv[1])],
        "x": tx,
        "y": ty,
        "H_m": t_h,
        "lat_deg": lat,
        "lon_deg": lon,
        "h_m": t_h + GEOID_UNDULATION_M,
    }
    trees = _trees(rng, np.vstack([pts[:, :2] - (X0, Y0), [[p.x, p.y], _CAMERA_DXY]]))
    _write_dem_tiles(out, rng)
    _write_lidar(out, rng, trees)
    _write_ortho(out, rng, trees)
    _write_roads(out)
    (out / "cam1_intrinsics.json").write_text(json.dumps(_INTRINSICS, indent=2) + "\n")
    (out / "cam1_survey.json").write_text(json.dumps(survey, indent=2) + "\n")
    truth = {
        "geoid_undulation_m": GEOID_UNDULATION_M,
        "camera": cam,
        "survey": survey,
        "target": target,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth


def main(argv: list[str] | None = None) -> int:
    """Command line: ``make_real_site_inputs.py OUT_DIR``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder to write the raw inputs into")
    args = parser.parse_args(argv)
    truth = make_real_site_inputs(args.out)
    s = truth["survey"]
    sys.stdout.write(
        f"wrote {len(list(args.out.iterdir()))} files to {args.out}; camera survey: "
        f"{s['position']} grid az {s['grid_azimuth_deg']} tilt {s['tilt_deg']}; "
        f"target pixel {truth['target']['pixel']}\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
