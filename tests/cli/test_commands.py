from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from demtrack.cli import main
from demtrack.core.site.folder import load_site
from demtrack.core.terrain.dem import Dem


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_geolocate_json_matches_the_engine(capsys, sample_site_dir):
    status, out, _ = run(
        capsys,
        "geolocate",
        "--site",
        str(sample_site_dir),
        "--sensor",
        "cam3",
        "--pixel",
        "700",
        "500",
        "--rule",
        "all",
        "--json",
    )
    assert status == 0
    doc = json.loads(out)
    site = load_site(sample_site_dir)
    (g,) = site.geolocator().geolocate(site.sensor("cam3").camera, [700.0], [500.0], rule="all")
    assert doc["status"] == g.status and len(doc["hits"]) == len(g.hits) >= 1
    for h, ref in zip(doc["hits"], g.hits, strict=True):
        assert [h["e_m"], h["n_m"], h["u_m"]] == pytest.approx(list(ref.p_enu), abs=1e-9)
        lat, lon, hh = site.frame.to_geodetic(*ref.p_enu)
        assert (h["lat_deg"], h["lon_deg"], h["h_m"]) == pytest.approx((lat, lon, hh))
        assert h["sigma_m"] > 0 and h["range_m"] > 0


def test_geolocate_text_lists_every_hit_and_marks_the_rule(capsys, sample_site_dir):
    status, out, _ = run(
        capsys,
        "geolocate",
        "--site",
        str(sample_site_dir),
        "--sensor",
        "cam1",
        "--pixel",
        "640",
        "600",
        "--rule",
        "last",
    )
    assert status == 0
    assert "cam1 (Museum roof) pixel (640, 600)" in out
    assert "hit 1" in out and "lat 40.35" in out and "*" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--sensor", "cam9", "--pixel", "1", "1"], "unknown sensor 'cam9'; this site has: cam1"),
        (["--sensor", "cam1", "--pixel", "5000", "1"], "pixel (5000, 1) is outside the 1280x720"),
        (["--sensor", "cam1", "--pixel", "nan", "1"], "is outside the"),
    ],
)
def test_geolocate_bad_input_is_one_line_and_status_2(capsys, sample_site_dir, argv, message):
    status, out, err = run(capsys, "geolocate", "--site", str(sample_site_dir), *argv)
    assert status == 2 and out == ""
    assert message in err and err.count("\n") == 1 and err.startswith("demtrack geolocate: error:")


def test_missing_site_is_one_line(capsys, tmp_path):
    status, _, err = run(
        capsys, "geolocate", "--site", str(tmp_path / "x"), "--sensor", "a", "--pixel", "1", "1"
    )
    assert status == 2 and "site folder not found" in err and err.count("\n") == 1


def test_calibrate_yaw_prints_residuals_and_flags_the_blunder(capsys, sample_site_dir):
    status, out, _ = run(
        capsys, "calibrate-yaw", "--site", str(sample_site_dir), "--sensor", "cam2"
    )
    assert status == 0
    truth = json.loads((sample_site_dir / "truth.json").read_text())["sensors"]["cam2"]
    assert f"mount yaw {truth['calibrated_mount_yaw_deg']:.4f} deg" in out
    assert "lot NE corner" in out and "OUTLIER" in out
    status, out, _ = run(
        capsys,
        "calibrate-yaw",
        "--site",
        str(sample_site_dir),
        "--sensor",
        "cam2",
        "--json",
        "--keep-outliers",
    )
    doc = json.loads(out)
    # The plain circular mean is dragged by the 2-degree blunder over 10 landmarks.
    assert doc["yaw_deg"] - truth["calibrated_mount_yaw_deg"] == pytest.approx(-0.2, abs=0.03)
    assert sum(lm["outlier"] for lm in doc["landmarks"]) == 1


def test_build_dem_from_npy_and_csv_with_fill(capsys, tmp_path, sample_site_dir):
    rng = np.random.default_rng(0)
    pts = np.column_stack(
        [rng.uniform(-20, 20, 4000), rng.uniform(-20, 20, 4000), rng.normal(5.0, 0.1, 4000)]
    )
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) > 5]  # a hole in the middle
    np.save(tmp_path / "p.npy", pts)
    np.savetxt(tmp_path / "p.csv", pts, delimiter=",", header="x,y,z", comments="")
    site = str(sample_site_dir)
    for name in ("p.npy", "p.csv"):
        out_tif = tmp_path / f"{name}.tif"
        status, out, _ = run(
            capsys,
            "build-dem",
            str(tmp_path / name),
            "-o",
            str(out_tif),
            "--cell",
            "1",
            "--bounds",
            "-20",
            "-20",
            "20",
            "20",
            "--site",
            site,
            "--fill",
            str(sample_site_dir / "coarse_dem_30m.tif"),
        )
        assert status == 0 and "filled from" in out
        dem = Dem.read(out_tif)
        assert dem.grid.shape == (40, 40) and dem.count.sum() == len(pts)
        assert dem.filled[20, 20] and not dem.nodata.any()
        ref = Dem.from_points(pts, 1.0, bounds=(-20, -20, 20, 20))
        has = ref.count > 0
        np.testing.assert_allclose(dem.elevation[has], ref.elevation[has], atol=1e-5)


@pytest.mark.parametrize(
    ("content", "extra", "message"),
    [
        ("x,y,z\n1,2,3\n", [], "the points' CRS is missing"),
        ("x,y,z\n1,2\n", ["--crs", "EPSG:32617"], "malformed point file"),
        ("x,y,z\n1,2,3\n", ["--crs", "EPSG:4326"], "is not projected in metres"),
        ("x,y,z\n1,2,3\n", ["--crs", "EPSG:2272"], "is not projected in metres"),
    ],
)
def test_build_dem_bad_input(capsys, tmp_path, content, extra, message):
    (tmp_path / "p.csv").write_text(content)
    status, _, err = run(
        capsys, "build-dem", str(tmp_path / "p.csv"), "-o", str(tmp_path / "d.tif"), *extra
    )
    assert status == 2 and message in err and err.count("\n") == 1


@pytest.mark.parametrize(
    ("crs", "datum"),
    [
        ("EPSG:32617", "heights of the source points (their CRS states no vertical datum)"),
        ("EPSG:32617+5703", "heights of the source points: NAVD88 height"),
    ],
)
def test_build_dem_in_the_points_crs_states_their_vertical_datum(capsys, tmp_path, crs, datum):
    # Without --site the heights are the points' own, not the site frame's up coordinate.
    (tmp_path / "p.csv").write_text("x,y,z\n500000,4400000,300\n500001,4400001,301\n")
    status, _, err = run(
        capsys, "build-dem", str(tmp_path / "p.csv"), "-o", str(tmp_path / "d.tif"), "--crs", crs
    )
    assert status == 0, err
    assert Dem.read(tmp_path / "d.tif").vertical_datum == datum


def test_demo_walks_through_the_site(capsys, sample_site_dir):
    status, out, _ = run(capsys, "demo", "--walkthrough", "--site", str(sample_site_dir))
    assert status == 0
    assert out.count("every hit along the ray") == 3 and "lat 40.35" in out


def test_console_script_exit_status_and_no_traceback(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "demtrack.cli",
            "calibrate-yaw",
            "--site",
            str(tmp_path),
            "--sensor",
            "x",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert (
        proc.stderr.strip()
        == f"demtrack calibrate-yaw: error: not a site folder (no site.json): {tmp_path}"
    )


def test_build_dem_from_laz_in_utm_lands_in_the_site_frame(
    capsys, tmp_path, sample_site_dir, write_las
):
    from pyproj import Transformer

    rng = np.random.default_rng(1)
    e, n = rng.uniform(-10, 10, 3000), rng.uniform(-10, 10, 3000)
    site = load_site(sample_site_dir)
    lat, lon, _ = site.frame.to_geodetic(e, n, np.zeros_like(e))
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(lon, lat)
    h = site.frame.h_m + 10.0  # ellipsoidal heights, 10 m above the anchor
    classes = np.where(np.arange(3000) % 3 == 0, 5, 2).astype(np.uint8)  # a third are trees
    z = np.where(classes == 2, h, h + 8.0)
    write_las(tmp_path / "p.laz", np.column_stack([x, y, z]), classes, np.ones(3000, np.uint8))
    status, out, _ = run(
        capsys,
        "build-dem",
        str(tmp_path / "p.laz"),
        "-o",
        str(tmp_path / "d.tif"),
        "--site",
        str(sample_site_dir),
        "--cell",
        "2",
        "--bounds",
        "-10",
        "-10",
        "10",
        "10",
        "--ground-only",
    )
    assert status == 0, out
    dem = Dem.read(tmp_path / "d.tif")
    assert dem.count.sum() == 2000
    # Local up of a point 10 m above the anchor's ellipsoid height, <= 10 m away: 10 m
    # minus the earth's curvature drop (d^2 / 2R < 0.01 mm).
    np.testing.assert_allclose(dem.elevation[dem.count > 0], 10.0, atol=2e-3)


def test_viewshed_reports_coverage_and_writes_a_raster(capsys, tmp_path, sample_site_dir):
    import rasterio

    from demtrack.core.visibility.target_heights import DEFAULT_TARGET_HEIGHT_M
    from demtrack.core.visibility.viewshed import viewshed

    out_tif = tmp_path / "cov.tif"
    status, out, _ = run(capsys, "viewshed", "--site", str(sample_site_dir), "-o", str(out_tif))
    assert status == 0 and "seen by >= 1 sensor" in out and "blind spots" in out
    site = load_site(sample_site_dir)
    with rasterio.open(out_tif) as src:
        count, cam1 = src.read(1), src.read(2)
        assert src.descriptions[1] == "seen_by_cam1"
    ref = viewshed(site.dem, site.sensor("cam1").camera, target_height_m=DEFAULT_TARGET_HEIGHT_M)
    np.testing.assert_array_equal(cam1.astype(bool), ref)
    assert count.max() <= len(site.sensors) and (count >= 1).any()
