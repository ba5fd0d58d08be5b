"""``demtrack build-dem --new-site``: a site from a point cloud alone, and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from geoid_oracle import egm96_n
from pyproj import CRS, Transformer

from demtrack.cli import main
from demtrack.core.geo.geoid import EGM96_GRID, find_grid
from demtrack.core.site.folder import load_site
from demtrack.core.terrain.pointcloud import read_point_cloud

FOOT_M = 0.3048
N_GEOID = -21.5


def egm96_grid():
    return find_grid(EGM96_GRID)


def run(capsys, *argv):
    try:
        status = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's refusals
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def test_a_site_from_the_autzen_tile_in_feet(capsys, tmp_path, autzen_laz):
    root = tmp_path / "autzen"
    status, out, err = run(
        capsys, "build-dem", autzen_laz, "--new-site", root,
        "--vertical-datum", "orthometric", "--geoid-undulation", N_GEOID,
    )  # fmt: skip
    assert status == 0, err
    print(out)
    assert "horizontal unit foot (0.3048 m)" in out and "interpolate tin" in out
    assert "h = H + N with N from the site's constant geoid undulation N = -21.5 m" in out
    assert "holes (11." in out
    site = load_site(root)
    assert site.geoid_undulation_m == N_GEOID
    # The DEM passes through the ground points: convert them independently (pyproj).
    cloud = read_point_cloud(autzen_laz).select(ground_only=True)
    x, y, z = cloud.xyz.T
    lon, lat = Transformer.from_crs(
        CRS.from_wkt(cloud.crs_wkt), "EPSG:4326", always_xy=True
    ).transform(x, y)
    e, n, u = site.frame.to_enu(lat, lon, z * FOOT_M + N_GEOID)
    dz = site.dem.sample(e, n) - u
    ok = np.isfinite(dz)
    assert ok.mean() > 0.999
    rms = float(np.sqrt(np.mean(dz[ok] ** 2)))
    assert rms < 0.06 and abs(float(np.mean(dz[ok]))) < 0.005
    assert not list(tmp_path.glob(".*building*"))


@pytest.mark.skipif(egm96_grid() is None, reason="needs proj-data's egm96_15.gtx")
def test_orthometric_points_through_egm96_per_point(capsys, tmp_path, autzen_laz):
    root = tmp_path / "autzen"
    status, out, err = run(
        capsys, "build-dem", autzen_laz, "--new-site", root, "--cell", "2",
        "--vertical-datum", "orthometric", "--geoid", "egm96",
    )  # fmt: skip
    assert status == 0, err
    assert "EGM96" in out
    site = load_site(root)
    assert site.geoid.kind == "grid" and site.geoid.name == "EGM96"
    cloud = read_point_cloud(autzen_laz).select(ground_only=True)
    x, y, z = cloud.xyz.T
    lon, lat = Transformer.from_crs(
        CRS.from_wkt(cloud.crs_wkt), "EPSG:4326", always_xy=True
    ).transform(x, y)
    n = egm96_n(lat, lon)  # the grid read by rasterio, interpolated independently
    assert site.geoid_undulation_m == pytest.approx(
        float(egm96_n(np.array([site.frame.lat_deg]), np.array([site.frame.lon_deg]))[0]),
        abs=1e-3,
    )
    e, nn, u = site.frame.to_enu(lat, lon, z * FOOT_M + n)
    dz = site.dem.sample(e, nn) - u
    ok = np.isfinite(dz)
    assert ok.mean() > 0.99 and abs(float(np.mean(dz[ok]))) < 0.01


def test_a_surface_model_is_above_the_terrain_model(capsys, tmp_path, autzen_laz):
    common = ("--vertical-datum", "ellipsoidal", "--cell", "2")
    assert run(capsys, "build-dem", autzen_laz, "--new-site", tmp_path / "t", *common)[0] == 0
    assert (
        run(
            capsys,
            "build-dem",
            autzen_laz,
            "--new-site",
            tmp_path / "s",
            "--surface",
            "dsm",
            *common,
        )[0]  # fmt: skip
        == 0
    )
    dtm, dsm = load_site(tmp_path / "t"), load_site(tmp_path / "s")
    assert dtm.frame == dsm.frame or abs(dtm.frame.h_m - dsm.frame.h_m) < 5.0
    ex, ny = dtm.dem.grid.centres()
    has = ~dtm.dem.nodata
    lat, lon, h = dtm.frame.to_geodetic(ex[has], ny[has], dtm.dem.elevation[has])
    e2, n2, u2 = dsm.frame.to_enu(lat, lon, h)
    top = dsm.dem.sample(e2, n2)
    ok = np.isfinite(top)
    assert ok.mean() > 0.95
    diff = top[ok] - u2[ok]
    # roofs, stands and trees stand metres above the ground; nowhere far below it
    assert np.percentile(diff, 1) > -0.5 and diff.max() > 10.0


def _one_line(capsys, argv, needle, root):
    status, out, err = run(capsys, *argv)
    assert status == 2 and needle in err and err.count("\n") == 1, err
    assert "Traceback" not in err and out == ""
    assert not root.exists() and not list(root.parent.glob(f".{root.name}.*"))


def test_bad_inputs_are_one_line_and_leave_nothing(capsys, tmp_path, write_las):
    root = tmp_path / "new"
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, 50, 200), rng.uniform(0, 50, 200), rng.normal(0, 1, 200)])
    xyz[:, :2] += (589_000.0, 4_468_000.0)
    np.save(tmp_path / "p.npy", xyz)
    write_las(tmp_path / "noground.las", xyz, np.ones(200, np.uint8), np.ones(200, np.uint8))
    write_las(tmp_path / "ok.las", xyz, np.full(200, 2, np.uint8), np.ones(200, np.uint8))
    (tmp_path / "bad.laz").write_bytes(b"LASF" + bytes(300))
    vd = ("--vertical-datum", "ellipsoidal")
    cases = [
        (["build-dem", tmp_path / "bad.laz", "--new-site", root, *vd], "cannot read LAS/LAZ"),
        (["build-dem", tmp_path / "p.npy", "--new-site", root, "--surface", "dsm", *vd],
         "states no CRS"),
        (["build-dem", tmp_path / "noground.las", "--new-site", root, *vd], "no ground points"),
        (["build-dem", tmp_path / "p.npy", "--new-site", root, *vd, "--crs", "EPSG:32617"],
         "needs classified points"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, *vd, "--bounds", "1e5", "1e5",
          "1.1e5", "1.1e5"], "inside"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, *vd, "--crs",
          'ENGCRS["lab",EDATUM["x"],CS[Cartesian,2],AXIS["x",east],AXIS["y",north],'
          'LENGTHUNIT["metre",1]]'], "neither projected nor geographic"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, *vd, "--z-unit", "yd"],
         "--z-unit"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root], "--vertical-datum"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, "--vertical-datum",
          "orthometric"], "--geoid egm96|FILE"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, "--vertical-datum",
          "orthometric", "--geoid", "none"], "needs a geoid"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, "--vertical-datum",
          "orthometric", "--geoid", tmp_path / "missing.gtx"], "geoid grid not found"),
        (["build-dem", tmp_path / "ok.las", "--new-site", root, *vd, "--first-returns",
          "--ground-only", "--bounds", "0", "0", "1", "1"], "inside"),
    ]  # fmt: skip
    for argv, needle in cases:
        _one_line(capsys, argv, needle, root)


def test_an_existing_folder_is_not_overwritten(capsys, tmp_path, write_las):
    rng = np.random.default_rng(1)
    xyz = np.column_stack([rng.uniform(0, 50, 300), rng.uniform(0, 50, 300), rng.normal(0, 1, 300)])
    xyz[:, :2] += (589_000.0, 4_468_000.0)
    write_las(tmp_path / "ok.las", xyz, np.full(300, 2, np.uint8), np.ones(300, np.uint8))
    root = tmp_path / "site"
    root.mkdir()
    (root / "keep.txt").write_text("mine")
    status, _, err = run(
        capsys, "build-dem", tmp_path / "ok.las", "--new-site", root,
        "--vertical-datum", "ellipsoidal",
    )  # fmt: skip
    assert status == 2 and "not an empty folder" in err
    assert sorted(p.name for p in root.iterdir()) == ["keep.txt"]
    (root / "keep.txt").unlink()  # an empty folder is taken
    status, out, err = run(
        capsys, "build-dem", tmp_path / "ok.las", "--new-site", root,
        "--vertical-datum", "ellipsoidal", "--interpolate", "none",
    )  # fmt: skip
    assert status == 0, err
    assert "interpolate none" in out
    assert load_site(root).dem.filled.sum() == 0


@pytest.mark.parametrize("flag", [["--name", "x"], ["--vertical-datum", "ellipsoidal"]])
def test_new_site_options_without_new_site_are_refused(capsys, tmp_path, flag):
    np.save(tmp_path / "p.npy", np.random.default_rng(2).uniform(0, 10, (50, 3)))
    status, _, err = run(capsys, "build-dem", tmp_path / "p.npy", "-o", tmp_path / "d.tif", *flag)
    assert status == 2 and "--new-site" in err and not (tmp_path / "d.tif").exists()


def test_bench_lidar_holdout_prints_the_comparison(capsys, autzen_laz):
    status, out, _ = run(capsys, "bench", "lidar-holdout", autzen_laz)
    assert status == 0
    assert "scipy Delaunay TIN (peer)" in out and "vs peer" in out
    ratio = float(out.split("demtrack TIN grid (bilinear fit)")[1].split()[-1])
    assert ratio <= 1.0
