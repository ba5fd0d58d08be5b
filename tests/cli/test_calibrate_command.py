"""``demtrack calibrate`` and ``demtrack convert-gcps`` end to end on a real site folder.

The site is made the way a user makes one (``import-dem`` from a UTM GeoTIFF, ``add-camera``
with ``--image``); GCPs are ground points of a known camera (oracle: that camera). Bad
input is one line, exit status 2, and the site folder byte-identical afterwards.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import Transformer

from demtrack.cli import main
from demtrack.core.camera.pinhole import Camera
from demtrack.core.site.folder import load_site

UTM = "EPSG:32617"
LAT0, LON0 = 40.3573, -79.6208
TO_UTM = Transformer.from_crs("EPSG:4326", UTM, always_xy=True)
X0, Y0 = (float(np.floor(v)) for v in TO_UTM.transform(LON0, LAT0))


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def snapshot(root):
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def site_parent(tmp_path_factory):
    """A folder holding ``site/`` (DEM from a UTM tile, camera cam1 added with an image)."""
    d = tmp_path_factory.mktemp("cal")
    t = Affine(5.0, 0.0, X0 - 800.0, 0.0, -5.0, Y0 + 800.0)
    cols, rows = np.meshgrid(np.arange(320) + 0.5, np.arange(320) + 0.5)
    x, y = t @ (cols, rows)
    z = 300.0 + 0.03 * (x - X0) + 0.05 * (y - Y0) + 4.0 * np.sin((x - X0) / 90.0)
    with rasterio.open(d / "dem.tif", "w", driver="GTiff", height=320, width=320, count=1,
                       dtype="float32", transform=t, crs=UTM) as dst:  # fmt: skip
        dst.write(z[None].astype("float32"))
    (d / "still.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 64)
    root = d / "site"
    imp = ["import-dem", "--site", root, d / "dem.tif", "--vertical-datum", "ellipsoidal",
           "--cell", "2", "--bounds", "-500", "-500", "500", "500"]  # fmt: skip
    assert main([str(a) for a in imp]) == 0
    add = ["add-camera", "--site", root, "--id", "cam1", "--position", X0, Y0 - 300, 325,
           "--crs", UTM, "--vertical-datum", "ellipsoidal", "--az", 10, "--tilt", -6,
           "--fx", 1200, "--width", 1600, "--height", 1200, "--image", d / "still.png"]  # fmt: skip
    assert main([str(a) for a in add]) == 0
    return d


def truth_camera(site):
    cam = load_site(site).sensor("cam1").camera
    az, tilt, roll = cam.azimuth_tilt_roll_deg()
    pos = cam.position_enu
    return Camera.from_azimuth_tilt_roll(cam.intrinsics, pos, az + 1.5, tilt - 0.7, 0.4)


def write_gcps(site, path, n=12, seed=0, blunder=None, lift=None):
    """GCPs where rays of the truth camera meet the DEM, 0.3 px noise; site-frame coords."""
    s = load_site(site)
    cam = truth_camera(site)
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(60, 1540, 4 * n), rng.uniform(700, 1150, 4 * n)
    fixes = s.geolocator().geolocate(cam, u, v)
    rows = []
    for k, fx in enumerate(fixes):
        if fx.best is None or len(rows) == n:
            continue
        p = np.array(fx.best.p_enu, float)
        uu, vv = u[k] + rng.normal(0, 0.3), v[k] + rng.normal(0, 0.3)
        if blunder is not None and len(rows) == blunder:
            uu += 40.0
        if lift is not None and len(rows) == lift:
            # A point 2.5 m above the terrain (a mast top), seen where it is: consistent
            # with the camera, not with the DEM.
            p[2] += 2.5
            pu, pv, _ = cam.project(p)
            uu, vv = float(pu[0]) + rng.normal(0, 0.3), float(pv[0]) + rng.normal(0, 0.3)
        rows.append(f"g{len(rows)},{uu:.3f},{vv:.3f},{p[0]:.4f},{p[1]:.4f},{p[2]:.4f}")
    path.write_text("# crs: local\nname,u,v,x,y,z\n" + "\n".join(rows) + "\n")
    return path


def test_relative_site_with_an_image_writes_back(capsys, site_parent, tmp_path, monkeypatch):
    """Issue 27: '--site site' (relative) with an --image camera died on write-back."""
    monkeypatch.chdir(site_parent)
    gcps = write_gcps("site", tmp_path / "g.csv")
    want = truth_camera("site").azimuth_tilt_roll_deg()
    status, out, err = run(capsys, "calibrate", "--site", "site", "--sensor", "cam1",
                           "--gcps", gcps)  # fmt: skip
    assert status == 0, err
    assert "Traceback" not in err and "written to site/site.json" in out
    fitted = load_site("site").sensor("cam1")
    assert fitted.camera.azimuth_tilt_roll_deg() == pytest.approx(want, abs=0.05)
    assert (
        json.loads((site_parent / "site" / "site.json").read_text())["sensors"][0]["image"]
        == "images/cam1.png"
    )
    assert not list((site_parent / "site").glob(".*.part"))
    # The same with an absolute path, then back through a relative one with '..'.
    status, out, err = run(capsys, "calibrate", "--site", site_parent / "site", "--sensor",
                           "cam1", "--gcps", gcps)  # fmt: skip
    assert status == 0, err
    monkeypatch.chdir(site_parent / "site" / "images")
    status, out, err = run(capsys, "calibrate", "--site", "..", "--sensor", "cam1",
                           "--gcps", gcps, "--json")  # fmt: skip
    assert status == 0, err
    assert json.loads(out)["written"] is True


def test_report_flags_a_blunder_and_a_gcp_above_the_dem(capsys, site_parent, tmp_path):
    site = site_parent / "site"
    gcps = write_gcps(site, tmp_path / "g.csv", n=14, blunder=3, lift=6)
    argv = ["calibrate", "--site", site, "--sensor", "cam1", "--gcps", gcps, "--dry-run"]
    status, out, err = run(capsys, *argv, "--free", "yaw,tilt,roll,fx,fy")
    assert status == 0, err
    rows = {ln.split()[0]: ln for ln in out.splitlines()[5:] if ln.startswith("  g")}
    assert "OUTLIER, excluded" in rows["g3"] and "OUTLIER" not in rows["g6"]
    assert "DEM: height 2.50 m above the DEM" in rows["g6"] and "passes over" in rows["g6"]
    assert sum("DEM:" in r for r in rows.values()) == 1
    assert "over the 13 GCPs kept in the fit" in out and "over all 14 GCPs" in out
    assert "dry run: site.json not changed" in out
    for col in ("LOO horiz m", "LOO vert m", "dh m", "ray"):
        assert col in out
    status, out, err = run(capsys, *argv, "--free", "yaw,tilt,roll,fx,fy", "--json",
                           "--exclude-dem-flagged")  # fmt: skip
    doc = json.loads(out)
    assert doc["n_kept"] == 12 and doc["gcps"][6]["excluded"] and doc["gcps"][6]["dem_flagged"]
    assert doc["gcps"][6]["dh_m"] == pytest.approx(2.5, abs=0.05)
    assert set(doc["sigmas"]) == {"yaw", "tilt", "roll", "fx", "fy"}
    assert len(doc["covariance"]) == 5 and doc["rmse_all_px"] > doc["rmse_kept_px"]
    assert doc["leave_one_out"]["kept_dem_consistent"]["horizontal_rms_m"] < 1.0


def test_imgraft_file_through_convert_gcps_and_directly(capsys, site_parent, tmp_path):
    site = site_parent / "site"
    csv = write_gcps(site, tmp_path / "g.csv", n=10)
    s = load_site(site)
    rows = [r.split(",") for r in csv.read_text().splitlines()[2:]]
    # ImGRAFT: x y z u v in a projected CRS, 1-based pixels.
    to_utm = Transformer.from_crs("EPSG:4979", "EPSG:32617", always_xy=True)
    lines = ["% GCPs for cam1", "% X Y Z U V"]
    for r in rows:
        lat, lon, h = s.frame.to_geodetic(float(r[3]), float(r[4]), float(r[5]))
        x, y, z = to_utm.transform(lon, lat, h)
        lines.append(f"{x:.4f} {y:.4f} {z:.4f} {float(r[1]) + 1:.3f} {float(r[2]) + 1:.3f}")
    (tmp_path / "g.txt").write_text("\n".join(lines) + "\n")
    status, out, err = run(capsys, "convert-gcps", tmp_path / "g.txt", "-o", tmp_path / "c.csv",
                           "--format", "imgraft", "--crs", "EPSG:32617", "--vertical",
                           "ellipsoidal")  # fmt: skip
    assert status == 0, err and "10 GCPs" in out
    common = ["calibrate", "--site", site, "--sensor", "cam1", "--dry-run", "--json"]
    a = json.loads(run(capsys, *common, "--gcps", tmp_path / "c.csv")[1])
    b = json.loads(run(capsys, *common, "--gcps", tmp_path / "g.txt", "--gcp-format",
                       "imgraft", "--gcp-crs", "EPSG:32617", "--gcp-vertical",
                       "ellipsoidal")[1])  # fmt: skip
    c = json.loads(run(capsys, *common, "--gcps", csv)[1])
    for name in ("yaw", "tilt", "roll"):
        assert a["values"][name] == pytest.approx(c["values"][name], abs=1e-5)
        assert b["values"][name] == pytest.approx(c["values"][name], abs=1e-5)


def _refused(capsys, root, argv, message):
    before = snapshot(root)
    status, out, err = run(capsys, *argv)
    assert status == 2, (out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err, err
    assert snapshot(root) == before and not list(root.rglob("*.part"))


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--free", "yaw,zoom"], "unknown parameter(s) zoom"),
        (["--free", "f,fx"], "free either f or fx,fy"),
        (["--free", "yaw,fx", "--bound", "fx=2000,3000"], "excludes its starting value 1200"),
        (["--free", "yaw,fx", "--bound", "fx=1300,1100"], "lower bound must be below"),
        (["--free", "yaw,fx", "--bound", "tilt=-10,0"], "'tilt' is not a free parameter"),
        (["--free", "yaw,fx", "--prior", "fx=1200"], "is malformed: write NAME=VALUE,SIGMA"),
        (["--free", "yaw,x,y,z", "--prior-position", "1,2"], "write X,Y,Z,SIGMA"),
        (["--free", "yaw,x,y,z", "--prior-position", "1,2,3,-1"], "write X,Y,Z,SIGMA"),
        (
            ["--free", "yaw,x,y,z", "--prior-position", "1,2,3,1", "--prior-crs", "EPSG:32617"],
            "needs --prior-vertical",
        ),
        (["--free", "yaw,x,y,z", "--prior-crs", "EPSG:32617"], "without --prior-position"),
    ],
)
def test_bad_options_are_one_line_and_write_nothing(capsys, site_parent, tmp_path, extra, message):
    site = site_parent / "site"
    gcps = write_gcps(site, tmp_path / "g.csv", n=8)
    _refused(capsys, site, ["calibrate", "--site", site, "--sensor", "cam1", "--gcps", gcps,
                            *extra], message)  # fmt: skip


@pytest.mark.parametrize(
    ("text", "fmt", "message"),
    [
        ("# crs: local\nname,u,v,x,y,z\na,1,2,three,4,5\n", "csv", "data row 1 is malformed"),
        ("# crs: local\nname,u,v,x\na,1,2,3\n", "csv", "missing y,z"),
        ("# crs: local\nname,u,v,x,y,z\na,700,900,0,5000,0\nb,800,900,10,100,0\n", "csv",
         "'a' at E 0.0 N 5000.0 m is outside the DEM"),
        ("1 2 3 4\n", "imgraft", "line 1 must hold five numbers"),
    ],
)  # fmt: skip
def test_bad_gcp_files_are_one_line_and_write_nothing(capsys, site_parent, tmp_path, text, fmt,
                                                     message):  # fmt: skip
    site = site_parent / "site"
    (tmp_path / "bad.txt").write_text(text)
    _refused(capsys, site, ["calibrate", "--site", site, "--sensor", "cam1", "--gcps",
                            tmp_path / "bad.txt", "--gcp-format", fmt, "--gcp-crs", "local"],
             message)  # fmt: skip


def test_convert_gcps_refuses_without_a_crs_and_writes_nothing(capsys, tmp_path):
    (tmp_path / "g.txt").write_text("1 2 3 4 5\n")
    status, out, err = run(capsys, "convert-gcps", tmp_path / "g.txt", "-o", tmp_path / "o.csv",
                           "--format", "imgraft")  # fmt: skip
    assert status == 2 and "pass --crs" in err and err.count("\n") == 1
    assert not (tmp_path / "o.csv").exists() and not list(tmp_path.glob("*.part"))


# ------------------------------------------------------------------ real material


def test_real_case_through_import_dem_add_camera_and_calibrate(capsys, tmp_path):
    """weitsicht's tennis case the way a user would run it: the real DEM through
    import-dem, the peer's camera through add-camera (grid azimuth), its ground points as a
    GCP CSV in the DEM's CRS; calibrate from a start 1 deg off recovers the peer's pose."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "core" / "camera"))
    from weitsicht_tennis import CRS, DATA, _case, available, rotation_error_deg

    if not available():
        pytest.skip("weitsicht data not on this machine")
    case = _case()
    ref = case["peer_reference"]
    pose = ref["pose_conversion"]
    root = tmp_path / "tennis"
    x, y, _ = ref["grid"][12]["xyz"]
    imp = ["import-dem", "--site", root, DATA / "dem_01_gda94_mga55_ahd.tif", "--vertical-datum",
           "orthometric", "--geoid-undulation", 0, "--cell", 5, "--bounds", -700, -700, 700,
           700, "--anchor", *_anchor(x, y, ref["grid"][12]["xyz"][2])]  # fmt: skip
    status, out, err = run(capsys, *imp)
    assert status == 0, err
    r_grid = np.array(pose["R_world_cam_opencv_axes_in_dem_crs"])
    from demtrack.core.camera.pinhole import Intrinsics

    az, tilt, roll = Camera(
        Intrinsics(1, 1, 0, 0, 1, 1), np.zeros(3), r_grid
    ).azimuth_tilt_roll_deg()
    cam = case["camera"]
    w, h = case["image_size_px"]
    lens = ["--fx", cam["fx"], "--fy", cam["fy"], "--cx", cam["cx"], "--cy", cam["cy"], "--width",
            w, "--height", h, "--k1", cam["k1"], "--k2", cam["k2"], "--k3", cam["k3"], "--p1",
            cam["p1"], "--p2", cam["p2"]]  # fmt: skip
    pos = pose["position_in_dem_crs"]
    add = ["add-camera", "--site", root, "--id", "peer", "--position", *pos, "--crs", CRS,
           "--vertical-datum", "orthometric", "--north", "grid", "--az", az, "--tilt", tilt,
           "--roll", roll, *lens]  # fmt: skip
    status, out, err = run(capsys, *add)
    assert status == 0, err
    peer = load_site(root).sensor("peer").camera
    # The site's start: 1 deg off in azimuth, 0.5 deg in tilt.
    start = [*add[:-len(lens) - 6], "--az", az + 1.0, "--tilt", tilt + 0.5, "--roll", roll,
             *lens, "--replace"]  # fmt: skip
    start[start.index("peer")] = "cam"
    assert run(capsys, *start)[0] == 0
    rows = ["# crs: " + CRS, "# vertical: orthometric", "name,u,v,x,y,z"]
    for p in [*ref["grid"], *ref["example_points_01_02_tennis_court"]]:
        rows.append(f"{p['id']},{p['pixel_center_origin'][0]},{p['pixel_center_origin'][1]},"
                    f"{p['xyz'][0]},{p['xyz'][1]},{p['xyz'][2]}")  # fmt: skip
    (tmp_path / "gcps.csv").write_text("\n".join(rows) + "\n")
    status, out, err = run(capsys, "calibrate", "--site", root, "--sensor", "cam", "--gcps",
                           tmp_path / "gcps.csv", "--free", "yaw,tilt,roll", "--json")  # fmt: skip
    assert status == 0, err
    doc = json.loads(out)
    fitted = load_site(root).sensor("cam").camera
    # The remaining difference is the peer's grid-as-Cartesian geometry (see
    # tests/core/camera/test_gcp_weitsicht_peer.py): hundredths of a degree at most.
    assert rotation_error_deg(fitted, peer) < 0.02
    assert doc["rmse_kept_px"] < 2.0 and not any(g["dem_flagged"] for g in doc["gcps"])
    assert doc["leave_one_out"]["kept_dem_consistent"]["horizontal_rms_m"] < 0.3


def _anchor(x, y, h):
    lon, lat = Transformer.from_crs("EPSG:28355", "EPSG:4326", always_xy=True).transform(x, y)
    return [round(lat, 7), round(lon, 7), round(h, 3)]


def test_prior_position_in_utm_pins_the_camera(capsys, site_parent, tmp_path):
    site = site_parent / "site"
    gcps = write_gcps(site, tmp_path / "g.csv", n=10)
    s = load_site(site)
    cam = s.sensor("cam1").camera
    lat, lon, h = s.frame.to_geodetic(*cam.position_enu)
    x, y = TO_UTM.transform(lon, lat)
    common = ["calibrate", "--site", site, "--sensor", "cam1", "--gcps", gcps, "--dry-run",
              "--json", "--free", "yaw,tilt,roll,x,y,z"]  # fmt: skip
    status, out, err = run(capsys, *common, "--prior-position", f"{x:.4f},{y:.4f},{h:.4f},0.001",
                           "--prior-crs", UTM, "--prior-vertical", "ellipsoidal")  # fmt: skip
    assert status == 0, err
    doc = json.loads(out)
    got = [doc["values"][k] for k in ("x", "y", "z")]
    assert got == pytest.approx(list(cam.position_enu), abs=0.01)
    assert doc["priors"]["x"][1] == 0.001 and doc["sigmas"]["z"] < 0.002


def test_write_back_keeps_the_ptz_fields(capsys, site_parent, tmp_path):
    """Calibrating a PTZ head rewrites its pose only: active, latency, gap, slew limits stay."""
    import shutil

    site_dir = tmp_path / "site"
    shutil.copytree(site_parent / "site", site_dir)
    manifest = site_dir / "site.json"
    doc = json.loads(manifest.read_text())
    ptz = {"active": True, "pose_latency_s": 0.08, "max_pose_gap_s": 0.3,
           "slew_limits": {"pan_rate_deg_s": 45.0}}  # fmt: skip
    doc["sensors"][0].update(ptz)
    manifest.write_text(json.dumps(doc))
    before = load_site(site_dir).sensor("cam1")
    assert before.active and before.pose_latency_s == 0.08
    gcps = write_gcps(site_dir, tmp_path / "g.csv")
    status, _, err = run(capsys, "calibrate", "--site", site_dir, "--sensor", "cam1",
                         "--gcps", gcps)  # fmt: skip
    assert status == 0, err
    fitted = load_site(site_dir).sensor("cam1")
    assert (fitted.active, fitted.pose_latency_s, fitted.max_pose_gap_s) == (True, 0.08, 0.3)
    assert fitted.slew_limits == {"pan_rate_deg_s": 45.0}
    assert fitted.camera.azimuth_tilt_roll_deg() != before.camera.azimuth_tilt_roll_deg()
    written = json.loads(manifest.read_text())["sensors"][0]
    assert {k: written[k] for k in ptz} == ptz
