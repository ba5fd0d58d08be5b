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
            p[2] += 2.5
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
