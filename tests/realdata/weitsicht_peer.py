"""demtrack against the monoplotting library weitsicht on its own real data.

The data (``/work/shared/data/weitsicht``, Apache-2.0, read-only, never copied into the
repository; see its README) hold bundle-adjusted aerial cameras over DEMs in compound CRSs
with orthometric heights, and weitsicht's own ground points for a 5 x 5 pixel grid, the
principal point and each example's pixels (``cases.json``). This module builds the same
scene with demtrack's user path and measures how far apart the two answers are:

* **site path**: ``demtrack import-dem`` (the DEM warped onto a true-north site grid in a
  local ENU frame, heights ``h = H + N`` with a constant geoid undulation ``N``),
  ``demtrack add-camera --rotation`` (the pose in the DEM's CRS), then the core
  ``Geolocator``; each hit is converted back to the DEM's CRS (``H = h - N``) by pyproj.
* **engine level, grid-Cartesian march**: demtrack's ray (origin and direction of the
  demtrack camera, turned back into the DEM CRS's grid axes at the camera) marched through
  the DEM CRS as if it were Cartesian, over bilinear patches between the DEM's own cell
  centres, as weitsicht does. Only the camera model (pixel convention, lens, rotation)
  can make this differ from the peer.
* **engine level, geodetic march**: the same ray marched in demtrack's ENU frame, each
  sample converted exactly to the DEM's CRS and compared with the DEM's own bilinear
  surface. The difference to the site path is the site grid's resampling alone; its
  difference to the peer is the peer's treatment of the map grid as a Cartesian frame
  (projection scale factor and earth curvature).

Run as a script (``python tests/realdata/weitsicht_peer.py``) it prints the table of
``docs/real-data.md``.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rasterio

__all__ = [
    "DATA_DIR",
    "EGM96_GRID",
    "T_MAX_M",
    "GridMarch",
    "PeerCase",
    "build_site",
    "differences",
    "egm96_undulation_m",
    "geodetic_march",
    "grid_march",
    "load_cases",
    "load_plane_cases",
    "plane_hits",
    "r_grid_site",
    "rays_in_grid_axes",
    "write_plane_dem",
    "site_hits_in_dem_crs",
]


def _data_dir() -> Path:
    """``$DEMTRACK_WEITSICHT_DATA``, else ``../shared/data/weitsicht`` beside the checkout."""
    if os.environ.get("DEMTRACK_WEITSICHT_DATA"):
        return Path(os.environ["DEMTRACK_WEITSICHT_DATA"])
    for d in (Path(__file__).resolve().parents[3] / "shared", Path("/work/shared")):
        if (d / "data" / "weitsicht" / "cases.json").is_file():
            return d / "data" / "weitsicht"
    return Path("/work/shared/data/weitsicht")


def _egm96_grid() -> Path:
    from demtrack.server.site_info import geoid_grid_path

    return geoid_grid_path() or Path("/usr/share/proj/egm96_15.gtx")


DATA_DIR = _data_dir()
EGM96_GRID = _egm96_grid()
T_MAX_M = 2000.0  # longer than every ray here (the cameras fly 120-960 m above ground)

# CRSs of the DEMs, horizontal part (the heights are orthometric: AHD, GHA).
DEM_CRS = {"tennis_court_dem01": "EPSG:28355", "ariel_flight_dtm": "EPSG:31287"}


@dataclass(frozen=True)
class PeerCase:
    """One camera of a DEM case, as weitsicht used it (pose already in the DEM's CRS).

    Attributes
    ----------
    key : str
        ``case_id/image``.
    dem_path : Path
        The GeoTIFF.
    dem_crs : str
        Its horizontal CRS; its heights are orthometric (AHD, GHA).
    intrinsics : dict
        ``fx, fy, cx, cy, width, height, k1, k2, p1, p2, k3, k4`` (OpenCV pixel origin).
    position : ndarray, shape (3,)
        Optical centre: easting, northing (m, DEM CRS), orthometric height (m).
    R_grid_cam : ndarray, shape (3, 3)
        OpenCV camera axes into the DEM CRS's grid axes (E, N, up).
    pixels : ndarray, shape (n, 2)
        ``(u, v)`` with (0, 0) the centre of the top-left pixel.
    ids : list of str
        Pixel ids (``g00`` .. ``g44``, ``principal_point``, example points).
    xyz_peer : ndarray, shape (n, 3)
        weitsicht's ground points: easting, northing, orthometric height (DEM CRS).
    gsd_m : ndarray, shape (n,)
        weitsicht's ground sampling distance at each point (m).
    undulation_m : float or None
        EGM96 ``N`` weitsicht used for this pose, where it converted one (ariel).
    plane_h_m : ndarray, shape (n,), or None
        Plane cases: the ellipsoidal height of each of weitsicht's points on its 0 m
        EGM96 plane (``dem_path`` is then a flat GeoTIFF written by :func:`write_plane_dem`,
        heights ellipsoidal, and ``dem_crs`` is UTM 36N).
    """

    key: str
    dem_path: Path
    dem_crs: str
    intrinsics: dict[str, Any]
    position: np.ndarray
    R_grid_cam: np.ndarray  # noqa: N815
    pixels: np.ndarray
    ids: list[str]
    xyz_peer: np.ndarray
    gsd_m: np.ndarray
    undulation_m: float | None
    plane_h_m: np.ndarray | None = None


def _intrinsics(cam: dict[str, Any], size: list[int]) -> dict[str, Any]:
    out = {k: float(cam[k]) for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4")}
    out["width"], out["height"] = int(size[0]), int(size[1])
    return out


def _points(*groups: list[dict[str, Any]]) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray]:
    pts = [p for g in groups for p in g if p.get("hit", True)]
    uv = np.array([p["pixel_center_origin"] for p in pts], dtype=float)
    return (
        uv,
        [p["id"] for p in pts],
        np.array([p["xyz"] for p in pts], dtype=float),
        np.array([p["gsd_m"] for p in pts], dtype=float),
    )


def load_cases(data_dir: Path = DATA_DIR) -> list[PeerCase]:
    """The DEM cases of ``cases.json``: tennis court and the three ariel images."""
    doc = json.loads((data_dir / "cases.json").read_text(encoding="utf-8"))
    by_id = {c["id"]: c for c in doc["cases"]}
    out = []
    t = by_id["tennis_court_dem01"]
    ref = t["peer_reference"]
    conv = ref["pose_conversion"]
    uv, ids, xyz, gsd = _points(ref["grid"], ref["example_points_01_02_tennis_court"])
    out.append(
        PeerCase(
            "tennis_court_dem01",
            data_dir / t["dem"]["file"],
            DEM_CRS["tennis_court_dem01"],
            _intrinsics(t["camera"], t["image_size_px"]),
            np.array(conv["position_in_dem_crs"], dtype=float),
            np.array(conv["R_world_cam_opencv_axes_in_dem_crs"], dtype=float),
            uv,
            ids,
            xyz,
            gsd,
            None,
        )
    )
    a = by_id["ariel_flight_dtm"]
    for img in a["peer_reference"]["images"]:
        side = "right" if "right" in img["camera"] else "left"
        uv, ids, xyz, gsd = _points(img["grid"], img.get("example_points_03_02_polygon", []))
        out.append(
            PeerCase(
                f"ariel_flight_dtm/{img['image'].removesuffix('.jpg')}",
                data_dir / a["dem"]["file"],
                DEM_CRS["ariel_flight_dtm"],
                _intrinsics(a["cameras"][side], a["image_size_px"]),
                np.array(img["position_in_dem_crs"], dtype=float),
                np.array(img["R_world_cam_opencv_axes_in_dem_crs"], dtype=float),
                uv,
                ids,
                xyz,
                gsd,
                float(img["egm96_undulation_N_m"]),
            )
        )
    return out


def load_plane_cases(dem_dir: Path, data_dir: Path = DATA_DIR) -> list[PeerCase]:
    """The plane cases (DSC00316 and the four dugong images), poses in UTM 36N + h.

    ``dem_dir`` is where :func:`write_plane_dem` puts each case's flat GeoTIFF.
    """
    doc = json.loads((data_dir / "cases.json").read_text(encoding="utf-8"))
    by_id = {c["id"]: c for c in doc["cases"]}
    images = [("dsc00316_meta_eor", by_id["dsc00316_meta_eor"]["peer_reference"])]
    images += [("dugong_survey", im) for im in by_id["dugong_survey"]["peer_reference"]["images"]]
    out = []
    for case_id, im in images:
        extra = im.get("example_point_04_02", []) + im.get("example_point_04_01", [])
        pts = [p for p in im.get("grid", []) + extra if p["hit"]]
        if not pts:  # dugong images 1, 2 and 4: only footprints were mapped
            continue
        uv, ids, xyz, gsd = _points(pts)
        name = Path(im["image"]).stem
        out.append(
            PeerCase(
                f"{case_id}/{name}",
                dem_dir / f"plane_{name}.tif",
                "EPSG:32636",
                _intrinsics(im["camera_from_metadata"], im["image_size"]),
                np.array(im["position"], dtype=float),
                np.array(im["R_world_cam_opencv_axes"], dtype=float),
                uv,
                ids,
                xyz,
                gsd,
                None,
                np.array([p["h_ellipsoidal"] for p in pts], dtype=float),
            )
        )
    return out


def write_plane_dem(case: PeerCase, half_m: float = 300.0, cell_m: float = 2.0) -> Path:
    """A flat GeoTIFF in UTM 36N at the median ellipsoidal height of the peer's plane hits.

    weitsicht's plane is 0 m EGM96, so its ellipsoidal height follows EGM96 across the
    footprint (a spread of 0.5-7 mm here); one height is what a flat DEM can hold.
    """
    from rasterio.transform import from_origin

    assert case.plane_h_m is not None
    n = int(round(2 * half_m / cell_m))
    x0 = math.floor(case.position[0] - half_m)
    y0 = math.ceil(case.position[1] + half_m)
    z = np.full((n, n), float(np.median(case.plane_h_m)), dtype=np.float32)
    profile = {
        "driver": "GTiff", "width": n, "height": n, "count": 1, "dtype": "float32",
        "crs": case.dem_crs, "transform": from_origin(x0, y0, cell_m, cell_m),
    }  # fmt: skip
    case.dem_path.parent.mkdir(parents=True, exist_ok=True)
    with rasterio.open(case.dem_path, "w", **profile) as dst:
        dst.write(z, 1)
    return case.dem_path


def plane_hits(origin: np.ndarray, d_grid: np.ndarray, h_m: np.ndarray) -> np.ndarray:
    """Rays cut with the horizontal planes ``z = h_m`` of the grid-Cartesian frame (analytic)."""
    t = (h_m - origin[2]) / d_grid[:, 2]
    return origin[None, :] + t[:, None] * d_grid


def egm96_undulation_m(lat_deg: float, lon_deg: float) -> float:
    """EGM96 ``N`` (m) at a point, from Debian proj-data's ``egm96_15.gtx`` (bilinear)."""
    from pyproj import Transformer

    tr = Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad"
        f" +step +proj=vgridshift +grids={EGM96_GRID} +multiplier=1"
        " +step +proj=unitconvert +xy_in=rad +xy_out=deg"
    )
    _, _, n = tr.transform(lon_deg, lat_deg, 0.0)
    return float(n)


# --------------------------------------------------------------------------- native DEM


class GridMarch:
    """The DEM's own surface: bilinear patches between its cell centres (numpy only).

    Parameters
    ----------
    path : Path
        GeoTIFF (``AREA_OR_POINT=Area``: the affine maps cell corners; a value belongs to
        its cell's centre).
    """

    def __init__(self, path: Path) -> None:
        with rasterio.open(path) as src:
            z = src.read(1).astype(np.float64)
            nodata = src.nodata
            t = src.transform
        if nodata is not None:
            z[z == nodata] = np.nan
        if t.b != 0.0 or t.d != 0.0:
            raise ValueError("rotated rasters are not handled here")
        self.z = z
        self.x0, self.dx, self.y0, self.dy = t.c, t.a, t.f, t.e  # dy < 0 (north-up)

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear height at ``(x, y)`` of the DEM CRS; NaN outside the centres' hull."""
        gx = (np.asarray(x) - self.x0) / self.dx - 0.5
        gy = (np.asarray(y) - self.y0) / self.dy - 0.5
        nr, nc = self.z.shape
        ok = (gx >= 0) & (gy >= 0) & (gx <= nc - 1) & (gy <= nr - 1)
        c0 = np.clip(np.floor(np.where(ok, gx, 0)), 0, nc - 2).astype(int)
        r0 = np.clip(np.floor(np.where(ok, gy, 0)), 0, nr - 2).astype(int)
        fx, fy = np.where(ok, gx, 0) - c0, np.where(ok, gy, 0) - r0
        z = self.z
        top = z[r0, c0] * (1 - fx) + z[r0, c0 + 1] * fx
        bot = z[r0 + 1, c0] * (1 - fx) + z[r0 + 1, c0 + 1] * fx
        return np.where(ok, top * (1 - fy) + bot * fy, np.nan)


def grid_march(
    dem: GridMarch, origin: np.ndarray, d_grid: np.ndarray, t_max: float, step: float = 0.5
) -> np.ndarray:
    """Intersect rays with the DEM, treating its CRS (E, N, H) as Cartesian (weitsicht's way).

    Parameters
    ----------
    origin : ndarray, shape (3,)
        Ray origin (E, N m; H m) in the DEM CRS.
    d_grid : ndarray, shape (n, 3)
        Unit directions in the DEM CRS's grid axes.
    t_max, step : float
        March length and step (m).

    Returns
    -------
    ndarray, shape (n, 3)
        First hits (E, N, H), NaN where none.
    """

    def above(t: np.ndarray) -> np.ndarray:
        p = origin[None, :] + np.broadcast_to(t, (d_grid.shape[0],))[:, None] * d_grid
        return p[:, 2] - dem.height(p[:, 0], p[:, 1])

    t = _march_rays(above, d_grid.shape[0], t_max, step)
    return origin[None, :] + t[:, None] * d_grid


def _march_rays(above, n: int, t_max: float, step: float, n_bisect: int = 60) -> np.ndarray:
    t_grid = np.arange(0.0, t_max + step, step)
    f = np.stack([above(np.full(n, t)) for t in t_grid])  # (steps, n)
    below = f <= 0.0
    first = np.where(below.any(axis=0), below.argmax(axis=0), 0)
    hit = first > 0
    t_lo = np.where(hit, t_grid[np.maximum(first - 1, 0)], np.nan)
    t_hi = np.where(hit, t_grid[first], np.nan)
    for _ in range(n_bisect):
        mid = 0.5 * (t_lo + t_hi)
        fm = above(np.nan_to_num(mid))
        t_hi = np.where(fm <= 0.0, mid, t_hi)
        t_lo = np.where(fm <= 0.0, t_lo, mid)
    return np.where(hit, 0.5 * (t_lo + t_hi), np.nan)


def geodetic_march(
    dem: GridMarch,
    frame: Any,
    dem_crs: str,
    undulation_m: float,
    origin_enu: np.ndarray,
    d_enu: np.ndarray,
    t_max: float,
    step: float = 0.5,
) -> np.ndarray:
    """Intersect demtrack's site-frame rays exactly with the DEM's own bilinear surface.

    Each sample ``p_enu`` of the ray is converted to the DEM CRS (pyproj, through the
    frame's ECEF conversion; ``H = h - N``) and compared with the DEM there.

    Returns
    -------
    ndarray, shape (n, 3)
        First hits in the site frame (E, N, U m), NaN where none.
    """

    def above(t: np.ndarray) -> np.ndarray:
        p = origin_enu[None, :] + np.broadcast_to(t, (d_enu.shape[0],))[:, None] * d_enu
        x, y, h = frame.from_enu_to_crs(
            p[:, 0], p[:, 1], p[:, 2], dem_crs, geoid_undulation_m=undulation_m, z_unit_m=1.0
        )
        return np.asarray(h) - dem.height(np.asarray(x), np.asarray(y))

    t = _march_rays(above, d_enu.shape[0], t_max, step)
    return origin_enu[None, :] + t[:, None] * d_enu


# --------------------------------------------------------------------------- demtrack user path


def _cli(argv: list[str]) -> str:
    from demtrack.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main([str(a) for a in argv])
    if rc != 0:
        raise RuntimeError(f"demtrack {argv[0]} failed ({rc}): {buf.getvalue()}")
    return buf.getvalue()


def build_site(
    root: Path,
    case: PeerCase,
    undulation_m: float,
    *,
    cell_m: float | None = None,
    half_width_m: float | None = None,
    sensor_id: str = "cam",
    pixel_shift: float = 0.0,
    datum: str = "orthometric",
) -> Path:
    """``import-dem`` + ``add-camera --rotation`` for one case, as a user would.

    The site's anchor is the camera's ground point below it (so the frame is local to the
    footprint); ``half_width_m`` limits the site grid to a square about it (for fine
    cells), ``cell_m`` overrides the DEM's native cell. ``pixel_shift`` moves the
    principal point by that many pixels in both axes (the half-pixel convention check).
    """
    from pyproj import Transformer

    x, y, h_cam = case.position
    lon, lat = Transformer.from_crs(case.dem_crs, "EPSG:4326", always_xy=True).transform(x, y)
    ground = float(GridMarch(case.dem_path).height(np.array([x]), np.array([y]))[0])
    if not (root / "site.json").is_file():
        argv = [
            "import-dem", "--site", root, "--vertical-datum", datum,
            "--geoid-undulation", f"{undulation_m:.4f}",
            "--anchor", f"{lat:.9f}", f"{lon:.9f}", f"{ground + undulation_m:.3f}",
        ]  # fmt: skip
        if cell_m is not None:
            argv += ["--cell", cell_m]
        if half_width_m is not None:
            w = half_width_m
            argv += ["--bounds", -w, -w, w, w]
        _cli([*argv, case.dem_path])
    intr = dict(case.intrinsics)
    intr["cx"] += pixel_shift
    intr["cy"] += pixel_shift
    intr_path = root / f"{sensor_id}_intrinsics.json"
    intr_path.write_text(json.dumps(intr), encoding="utf-8")
    _cli(
        [
            "add-camera", "--site", root, "--id", sensor_id, "--crs", case.dem_crs,
            "--vertical-datum", datum, "--position", *(f"{v:.4f}" for v in case.position),
            "--rotation", *(repr(float(v)) for v in case.R_grid_cam.ravel()),
            "--intrinsics", intr_path, "--replace",
        ]
    )  # fmt: skip
    return root


def site_hits_in_dem_crs(
    root: Path, case: PeerCase, sensor_id: str = "cam"
) -> tuple[np.ndarray, Any, Any]:
    """Geolocate the case's pixels through the core API; hits in the DEM CRS (E, N, H).

    Returns
    -------
    xyz : ndarray, shape (n, 3)
        First terrain hit of each pixel, converted with ``H = h - N`` (the site's N).
    site : Site
    camera : Camera
    """
    from demtrack.core.site.folder import load_site

    site = load_site(root)
    cam = site.sensor(sensor_id).camera
    geo = site.geolocator()
    res = geo.geolocate(cam, case.pixels[:, 0], case.pixels[:, 1], rule="first")
    p = np.array([g.selected[0].p_enu if g.selected else [np.nan] * 3 for g in res])
    x, y, big_h = site.frame.from_enu_to_crs(
        p[:, 0], p[:, 1], p[:, 2], case.dem_crs,
        geoid_undulation_m=site.geoid_undulation_m, z_unit_m=1.0,
    )  # fmt: skip
    return np.column_stack([x, y, big_h]), site, cam


def r_grid_site(site: Any, cam: Any, case: PeerCase) -> np.ndarray:
    """Rotation (3, 3) of site-frame vectors into the DEM CRS's grid axes at the camera.

    Site ENU -> the camera's own true ENU (through ECEF) -> grid axes (turned by the grid
    north that add-camera measured, :func:`~demtrack.core.camera.pose.grid_convergence_deg`).
    """
    from demtrack.core.camera.pose import grid_convergence_deg
    from demtrack.core.geo.geodesy import LocalFrame

    lat, lon, h = (float(v) for v in site.frame.to_geodetic(*cam.position_enu))
    r_true_site = LocalFrame(lat, lon, h).R_enu_ecef @ site.frame.R_enu_ecef.T
    g = math.radians(grid_convergence_deg(case.dem_crs, *case.position[:2]))
    r_grid_true = np.array(
        [[math.cos(g), -math.sin(g), 0.0], [math.sin(g), math.cos(g), 0.0], [0.0, 0.0, 1.0]]
    )
    return r_grid_true @ r_true_site


def rays_in_grid_axes(site: Any, cam: Any, case: PeerCase) -> tuple[np.ndarray, np.ndarray]:
    """demtrack's rays for the case's pixels in the DEM CRS: origin (E, N, H) and grid axes."""
    _, d_enu = cam.pixel_to_ray(case.pixels[:, 0], case.pixels[:, 1])
    d_grid = d_enu @ r_grid_site(site, cam, case).T
    x, y, big_h = site.frame.from_enu_to_crs(
        *cam.position_enu, case.dem_crs, geoid_undulation_m=site.geoid_undulation_m, z_unit_m=1.0
    )
    return np.array([float(x), float(y), float(big_h)]), d_grid


def differences(xyz: np.ndarray, peer: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal and vertical distances (m) of ``xyz`` from the peer's points."""
    return np.hypot(*(xyz[:, :2] - peer[:, :2]).T), np.abs(xyz[:, 2] - peer[:, 2])


# --------------------------------------------------------------------------- the table


def _row(name: str, path: str, xyz: np.ndarray, peer: np.ndarray) -> str:
    dh, dv = differences(xyz, peer)
    return (
        f"| {name} | {path} | {len(peer)} | {np.median(dh):.4f} | {dh.max():.4f} | "
        f"{np.median(dv):.4f} | {dv.max():.4f} |"
    )


def main(work: Path) -> None:  # pragma: no cover - the documented run
    """Print the comparison table (Markdown) for every case."""
    from pyproj import Transformer

    head = "| case | path | points | horiz. median (m) | horiz. max (m) | vert. median (m) | vert. max (m) |"  # noqa: E501
    print(head)  # noqa: T201
    print("|---|---|---:|---:|---:|---:|---:|")  # noqa: T201
    for case in load_cases():
        x, y, _ = case.position
        lon, lat = Transformer.from_crs(case.dem_crs, "EPSG:4326", always_xy=True).transform(x, y)
        n = case.undulation_m if case.undulation_m is not None else egm96_undulation_m(lat, lon)
        dem = GridMarch(case.dem_path)
        for label, cell, half in (
            ("site, native cells", None, None),
            ("site, 1 m cells", 1.0, 700.0),
        ):
            root = work / f"{case.key.replace('/', '_')}_{label.split()[1]}"
            build_site(root, case, n, cell_m=cell, half_width_m=half)
            xyz, site, cam = site_hits_in_dem_crs(root, case)
            print(_row(case.key, label, xyz, case.xyz_peer))  # noqa: T201
        origin, d_grid = rays_in_grid_axes(site, cam, case)
        # The peer's own origin: the camera position's round trip through the site frame
        # (up to 1 mm with MGI's 2-D Helmert, see docs/real-data.md) is not the camera model.
        hits = grid_march(dem, case.position, d_grid, T_MAX_M)
        print(_row(case.key, "grid-Cartesian march", hits, case.xyz_peer))  # noqa: T201
        o_enu, d_enu = cam.pixel_to_ray(case.pixels[:, 0], case.pixels[:, 1])
        p = geodetic_march(dem, site.frame, case.dem_crs, n, o_enu[0], d_enu, T_MAX_M)
        g = site.frame.from_enu_to_crs(*p.T, case.dem_crs, geoid_undulation_m=n, z_unit_m=1.0)
        print(_row(case.key, "geodetic march", np.column_stack(g), case.xyz_peer))  # noqa: T201
        trip = 1000 * np.abs(origin - case.position).max()
        print(f"| {case.key} | camera position round trip | | {trip:.2f} mm | | | |")  # noqa: T201
    for case in load_plane_cases(work / "planes"):
        write_plane_dem(case)
        root = build_site(work / case.key.replace("/", "_"), case, 0.0, datum="ellipsoidal")
        xyz, site, cam = site_hits_in_dem_crs(root, case)
        print(_row(case.key, "site, flat DEM (2 m)", xyz, case.xyz_peer))  # noqa: T201
        _, d_grid = rays_in_grid_axes(site, cam, case)
        hits = plane_hits(case.position, d_grid, case.plane_h_m)
        print(_row(case.key, "grid-Cartesian plane", hits, case.xyz_peer))  # noqa: T201


if __name__ == "__main__":  # pragma: no cover
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tmp))
