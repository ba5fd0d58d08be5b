"""A real site from raw inputs: import-dem, import-ortho, import-roads, add-camera,
calibrate --gcps, geolocate; and bad input refused with one line, nothing half-written.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import struct
import subprocess
import sys

import numpy as np
import pytest
import rasterio
import shapely
from affine import Affine
from pyproj import Transformer

from demtrack.cli import main
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.site.folder import load_site

UTM = "EPSG:32617"
LAT0, LON0 = 40.3573, -79.6208
TO_UTM = Transformer.from_crs("EPSG:4326", UTM, always_xy=True)
X0, Y0 = (float(np.floor(v)) for v in TO_UTM.transform(LON0, LAT0))
N_GEOID = -33.5


def h_utm(x, y):
    """Orthometric heights (m) of the raw DEM over UTM coordinates."""
    return 330.0 + 0.04 * (x - X0) + 0.08 * (y - Y0)


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def write_tif(path, data, transform, crs, dtype="float32", nodata=None):
    data = np.asarray(data)
    bands = data[None] if data.ndim == 2 else data
    profile = dict(driver="GTiff", height=bands.shape[1], width=bands.shape[2],
                   count=bands.shape[0], dtype=dtype, transform=transform)  # fmt: skip
    if crs:
        profile["crs"] = crs
    if nodata is not None:
        profile["nodata"] = nodata
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(bands.astype(dtype))
    return path


def gpkg_blob(geom, srs_id):
    # GeoPackage binary: 'GP', version 0, flags (little endian, envelope [minx maxx miny
    # maxy]), srs_id, envelope, then ISO WKB.
    minx, miny, maxx, maxy = geom.bounds
    header = b"GP" + bytes([0, 0b00000011]) + struct.pack("<i", srs_id)
    return header + struct.pack("<4d", minx, maxx, miny, maxy) + shapely.to_wkb(geom)


def write_gpkg(path, lines_xy, srs_id=32617):
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
        "INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, 'EPSG', ?, 'undefined', '')",
        ("WGS 84 / UTM zone 17N", srs_id, srs_id),
    )
    con.execute("INSERT INTO gpkg_geometry_columns VALUES ('roads','geom','LINESTRING',?,0,0)",
                (srs_id,))  # fmt: skip
    for k, xy in enumerate(lines_xy):
        blob = gpkg_blob(shapely.LineString(xy), srs_id)
        con.execute("INSERT INTO roads VALUES (?, ?, ?, ?)", (k + 1, blob, f"road {k}", 7.0))
    con.commit()
    con.close()
    return path


@pytest.fixture(scope="module")
def raw(tmp_path_factory):
    """Raw inputs as a user brings them: UTM DEM, UTM orthophoto, GeoPackage roads."""
    d = tmp_path_factory.mktemp("raw")
    t = Affine(5.0, 0.0, X0 - 800.0, 0.0, -5.0, Y0 + 800.0)
    cols, rows = np.meshgrid(np.arange(320) + 0.5, np.arange(320) + 0.5)
    x, y = t @ (cols, rows)
    write_tif(d / "dem_utm.tif", h_utm(x, y), t, UTM)
    t_o = Affine(2.0, 0.0, X0 - 600.0, 0.0, -2.0, Y0 + 600.0)
    co, ro = np.meshgrid(np.arange(600), np.arange(600))
    rgb = np.stack([co % 256, ro % 256, (co + ro) % 256])
    write_tif(d / "ortho_utm.tif", rgb, t_o, UTM, dtype="uint8")
    write_gpkg(d / "roads.gpkg", [[(X0 - 300, Y0 - 50), (X0 + 300, Y0 + 60)]])
    return d


def sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def snapshot(root):
    return {p.name: sha(p) for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def site(raw, tmp_path_factory):
    root = tmp_path_factory.mktemp("site") / "mysite"
    argv = ["import-dem", "--site", root, raw / "dem_utm.tif", "--vertical-datum",
            "orthometric", "--geoid-undulation", N_GEOID, "--cell", "2", "--bounds",
            "-500", "-500", "500", "500"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    return root


def test_import_dem_creates_a_site_with_heights_in_the_frame(site):
    s = load_site(site)
    assert s.dem.grid.cell_m == 2.0 and s.dem.grid.shape == (500, 500)
    assert s.geoid_undulation_m == N_GEOID
    # The anchor is the middle of the tile, on its terrain: local Z there ~ 0.
    assert abs(float(s.dem.sample(np.array([0.0]), np.array([0.0]))[0])) < 0.5
    e, n, u = s.frame.to_enu_from_crs(X0 + 100.0, Y0 + 200.0, h_utm(X0 + 100, Y0 + 200),
                                      UTM, geoid_undulation_m=N_GEOID)  # fmt: skip
    assert abs(float(s.dem.sample(np.array([e]), np.array([n]))[0]) - u) < 2e-3


def test_worked_example_ortho_roads_camera_calibrate_geolocate(capsys, site, raw, tmp_path):
    status, out, err = run(capsys, "import-ortho", "--site", site, raw / "ortho_utm.tif")
    assert status == 0, err
    s = load_site(site)
    with rasterio.open(s.orthophoto_path) as src:
        rgb = src.read()
        grid_t = src.transform
    # A cell's colour is the source pixel at its (UTM) position: pixel centres carry
    # col % 256 and row % 256, bilinear in between.
    e, n = 101.0, -57.0  # a cell centre on the 2 m grid
    c, r = ~grid_t @ (e, n)
    lat, lon, _ = s.frame.to_geodetic(e, n, float(s.dem.sample(np.array([e]), np.array([n]))[0]))
    x, y = TO_UTM.transform(lon, lat)
    col_src = (x - (X0 - 600.0)) / 2.0 - 0.5
    assert abs(int(rgb[0, int(r), int(c)]) - col_src % 256) <= 1.0

    status, out, err = run(capsys, "import-roads", "--site", site, raw / "roads.gpkg")
    assert status == 0, err
    s = load_site(site)
    assert len(s.roads) == 1 and s.roads.names == ("road 0",)
    start = np.asarray(s.roads.lines[0].coords)[0]
    # Roads are placed at the anchor's height (see core.site.road_io).
    e0, n0, _ = s.frame.to_enu_from_crs(X0 - 300, Y0 - 50, s.frame.h_m, UTM)
    assert np.hypot(start[0] - e0, start[1] - n0) < 1e-4

    # A camera surveyed in UTM (orthometric height), azimuth from grid north.
    intr = Intrinsics(1200.0, 1200.0, 799.5, 599.5, 1600, 1200)
    x_c, y_c = X0 - 150.0, Y0 - 300.0
    z_c = h_utm(x_c, y_c) + 25.0
    status, out, err = run(
        capsys, "add-camera", "--site", site, "--id", "cam1", "--position", x_c, y_c, z_c,
        "--crs", UTM, "--vertical-datum", "orthometric", "--az", 20.0, "--north", "grid",
        "--tilt", -6.0, "--roll", 0.0, "--fx", 1200, "--width", 1600, "--height", 1200,
    )  # fmt: skip
    assert status == 0, err
    assert "grid azimuth 20.0000 + convergence +0.8" in out
    truth = load_site(site).sensor("cam1").camera
    assert truth.intrinsics == intr

    # GCPs: ground points seen by a camera 2 deg off in yaw, as the site has it wrong.
    cam = Camera.from_azimuth_tilt_roll(intr, truth.position_enu,
                                        truth.azimuth_tilt_roll_deg()[0] + 2.0,
                                        *truth.azimuth_tilt_roll_deg()[1:])  # fmt: skip
    rng = np.random.default_rng(0)
    uu, vv = rng.uniform(50, 1550, 10), rng.uniform(700, 1150, 10)
    geo = load_site(site).geolocator()
    pts = np.array([g.best.p_enu for g in geo.geolocate(cam, uu, vv)])
    lat, lon, h = load_site(site).frame.to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2])
    gx, gy = TO_UTM.transform(lon, lat)
    lines = ["# crs: EPSG:32617", "# vertical: orthometric", "name,u,v,x,y,z"]
    for k in range(10):
        u_obs = uu[k] + rng.normal(0, 0.3) + (40.0 if k == 4 else 0.0)  # one blunder
        lines.append(f"gcp{k},{u_obs:.3f},{vv[k] + rng.normal(0, 0.3):.3f},"
                     f"{gx[k]:.4f},{gy[k]:.4f},{h[k] - N_GEOID:.4f}")  # fmt: skip
    (tmp_path / "gcps.csv").write_text("\n".join(lines) + "\n")
    status, out, err = run(capsys, "calibrate", "--site", site, "--sensor", "cam1",
                           "--gcps", tmp_path / "gcps.csv", "--free", "yaw,tilt,roll")  # fmt: skip
    assert status == 0, err
    assert "RMSE" in out and "leave-one-out ground error" in out
    assert [ln for ln in out.splitlines() if "OUTLIER, excluded" in ln][0].split()[0] == "gcp4"
    assert "written to" in out
    fitted = load_site(site).sensor("cam1").camera
    assert fitted.azimuth_tilt_roll_deg()[0] == pytest.approx(cam.azimuth_tilt_roll_deg()[0],
                                                              abs=0.02)  # fmt: skip
    assert not list(site.glob(".*.part"))

    status, out, err = run(capsys, "geolocate", "--site", site, "--sensor", "cam1",
                           "--pixel", uu[0], vv[0], "--json")  # fmt: skip
    assert status == 0, err
    hit = json.loads(out)["selected"][0]
    assert np.hypot(hit["e_m"] - pts[0, 0], hit["n_m"] - pts[0, 1]) < 1.0


# ------------------------------------------------------------------ bad input


def _one_line_error(capsys, argv, message, root=None):
    before = snapshot(root) if root is not None and root.exists() else None
    status, out, err = run(capsys, *argv)
    assert status == 2
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err, err
    if before is not None:
        assert snapshot(root) == before  # nothing changed, nothing half-written
        assert not list(root.rglob("*.part"))


def test_dem_without_crs_is_refused_and_no_site_is_made(capsys, tmp_path):
    t = Affine(5.0, 0.0, 0.0, 0.0, -5.0, 100.0)
    write_tif(tmp_path / "nocrs.tif", np.zeros((20, 20)), t, None)
    root = tmp_path / "new"
    _one_line_error(capsys, ["import-dem", "--site", root, tmp_path / "nocrs.tif",
                             "--vertical-datum", "ellipsoidal"], "has no CRS")  # fmt: skip
    assert not root.exists()


def test_camera_outside_the_dem_is_refused(capsys, site):
    _one_line_error(
        capsys,
        ["add-camera", "--site", site, "--id", "far", "--position", X0 + 5000, Y0, 400,
         "--crs", UTM, "--vertical-datum", "orthometric", "--az", 0, "--tilt", -5,
         "--fx", 1000, "--width", 640, "--height", 480],
        "is outside the DEM",
        site,
    )  # fmt: skip


def test_gcps_behind_the_camera_are_refused(capsys, site, tmp_path):
    s = load_site(site)
    # A camera placed by WGS84 lon/lat and ellipsoidal height, 40 m above the anchor.
    argv = ["add-camera", "--site", site, "--id", "cam2", "--position", LON0, LAT0,
            s.frame.h_m + 40.0, "--crs", "EPSG:4979", "--vertical-datum", "ellipsoidal",
            "--az", 0, "--tilt", -5, "--fx", 1000, "--width", 640, "--height", 480,
            "--replace"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    capsys.readouterr()
    # Points south of a camera looking north.
    (tmp_path / "g.csv").write_text(
        "# crs: local\nname,u,v,x,y,z\na,100,300,0,-100,0\nb,300,300,20,-120,0\n"
        "c,500,300,-20,-90,0\n"
    )
    _one_line_error(capsys, ["calibrate", "--site", site, "--sensor", "cam2", "--gcps",
                             tmp_path / "g.csv"], "is behind camera 'cam2'", site)  # fmt: skip


def test_truncated_laz_is_refused_and_no_dem_written(capsys, tmp_path, write_las):
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(X0, X0 + 50, 5000), rng.uniform(Y0, Y0 + 50, 5000),
                           rng.uniform(300, 310, 5000)])  # fmt: skip
    write_las(tmp_path / "p.laz", xyz, np.full(5000, 2, np.uint8), np.ones(5000, np.uint8))
    data = (tmp_path / "p.laz").read_bytes()
    (tmp_path / "cut.laz").write_bytes(data[: len(data) // 2])
    _one_line_error(capsys, ["build-dem", tmp_path / "cut.laz", "-o", tmp_path / "d.tif",
                             "--crs", UTM], "truncated or corrupt")  # fmt: skip
    assert not (tmp_path / "d.tif").exists() and not list(tmp_path.glob("*.part"))


def test_orthophoto_off_the_site_is_refused(capsys, site, tmp_path):
    t = Affine(2.0, 0.0, X0 + 20_000.0, 0.0, -2.0, Y0 + 20_000.0)
    write_tif(tmp_path / "far.tif", np.zeros((3, 50, 50)), t, UTM, dtype="uint8")
    _one_line_error(capsys, ["import-ortho", "--site", site, tmp_path / "far.tif"],
                    "does not overlap the site", site)  # fmt: skip


def test_console_script_prints_no_traceback(tmp_path):
    t = Affine(5.0, 0.0, 0.0, 0.0, -5.0, 100.0)
    write_tif(tmp_path / "nocrs.tif", np.zeros((20, 20)), t, None)
    proc = subprocess.run(
        [sys.executable, "-m", "demtrack.cli", "import-dem", "--site", str(tmp_path / "s"),
         str(tmp_path / "nocrs.tif"), "--vertical-datum", "ellipsoidal"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
