from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from server_helpers import AUTH

from demtrack.core.site.folder import load_site
from demtrack.core.site.orthophoto import read_orthophoto


def test_site_metadata_describes_frame_grid_and_datum(ro_client, sample_site_dir):
    site = load_site(sample_site_dir)
    body = ro_client.get("/api/site", headers=AUTH).json()
    assert body["frame"] == site.frame.to_dict()
    g = site.dem.grid
    assert body["dem"]["bounds_enu"] == list(g.bounds)
    assert (body["dem"]["nrows"], body["dem"]["ncols"]) == g.shape
    assert body["vertical_datum"] == site.dem.vertical_datum
    assert body["geoid_undulation_m"] == site.geoid_undulation_m
    # The sample site states EGM96: N at the real Bushy Run, and the datum named.
    assert body["geoid_undulation_m"] == pytest.approx(-33.97, abs=0.01)
    assert body["elevation_datum"] == "EGM96 geoid"
    assert body["crs_wkt"] == site.dem.crs_wkt
    assert body["sensors"] == sorted(site.sensors)
    lon0, lat0, lon1, lat1 = body["bounds_lonlat"]
    # the anchor lies inside the DEM, so inside its lon/lat box
    assert lon0 < site.frame.lon_deg < lon1 and lat0 < site.frame.lat_deg < lat1
    # the box's corners map back onto the grid's corners (to the ellipsoid's curvature)
    e, n, _ = site.frame.to_enu(lat0, lon0, site.frame.h_m)
    assert abs(e - g.x_min) < 0.5 and abs(n - g.y_min) < 0.5


def test_relief_png_is_on_the_dem_grid_with_transparent_holes(ro_client, sample_site_dir):
    dem = load_site(sample_site_dir).dem
    for kind in ("hillshade", "relief", "shaded-relief"):
        r = ro_client.get(f"/api/site/relief.png?kind={kind}", headers=AUTH)
        assert r.status_code == 200 and r.headers["content-type"] == "image/png"
        img = np.asarray(Image.open(io.BytesIO(r.content)))
        assert img.shape == (*dem.grid.shape, 4)
        np.testing.assert_array_equal(img[..., 3] == 0, np.isnan(dem.elevation))
    assert ro_client.get("/api/site/relief.png?kind=x", headers=AUTH).status_code == 422


def test_hillshade_oracle_sun_facing_slope_is_brighter():
    from demtrack.server.imagery import hillshade

    x = np.arange(50) * 1.0
    west_up = np.tile(x, (50, 1))  # rises to the east: faces west
    flat = np.zeros((50, 50))
    s_flat = hillshade(flat, 1.0, azimuth_deg=270, altitude_deg=45)
    s_west = hillshade(west_up, 1.0, azimuth_deg=270, altitude_deg=45)
    np.testing.assert_allclose(s_flat, np.sin(np.radians(45)))
    # slope 45 deg facing the sun at 45 deg altitude: lit head-on
    np.testing.assert_allclose(s_west[5:-5, 5:-5], 1.0, atol=1e-12)


def test_orthophoto_png_round_trips_the_geotiff(ro_client, sample_site_dir):
    site = load_site(sample_site_dir)
    rgb, grid = read_orthophoto(site.orthophoto_path)
    r = ro_client.get("/api/site/orthophoto.png", headers=AUTH)
    assert r.status_code == 200
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(r.content))), rgb)
    meta = ro_client.get("/api/site", headers=AUTH).json()["orthophoto"]
    assert meta["bounds_enu"] == list(grid.bounds)


def test_roads_lonlat_and_enu_agree(ro_client, sample_site_dir):
    site = load_site(sample_site_dir)
    ll = ro_client.get("/api/site/roads.geojson", headers=AUTH).json()
    enu = ro_client.get("/api/site/roads.geojson?frame=enu", headers=AUTH).json()
    assert len(ll["features"]) == len(enu["features"]) == len(site.roads)
    for a, b in zip(ll["features"], enu["features"], strict=True):
        lonlat = np.array(a["geometry"]["coordinates"])
        xy = np.array(b["geometry"]["coordinates"])
        e, n, _ = site.frame.to_enu(lonlat[:, 1], lonlat[:, 0], np.full(len(xy), site.frame.h_m))
        np.testing.assert_allclose(np.column_stack([e, n]), xy, atol=1e-3)


def test_sensor_footprints_lie_on_the_dem_and_back_project_to_the_border(
    ro_client, sample_site_dir
):
    site = load_site(sample_site_dir)
    sensors = ro_client.get("/api/sensors", headers=AUTH).json()
    assert [s["id"] for s in sensors] == sorted(site.sensors)
    for s in sensors:
        cam = site.sensor(s["id"]).camera
        fp = s["footprint"]
        assert fp["n_rays"] == len(fp["enu"]) or not fp["complete"]
        ring = fp["lonlat"]["coordinates"][0]
        assert ring[0] == ring[-1] and len(ring) == len(fp["enu"]) + 1
        p = np.array(fp["enu"])
        z = site.dem.sample(p[:, 0], p[:, 1])
        on_dem = np.isfinite(z) & (np.abs(z - p[:, 2]) < 1e-3)
        assert on_dem.sum() == fp["n_rays"] - fp["n_missed"]
        u, v, _ = cam.project(p[on_dem])
        w, h = cam.intrinsics.width, cam.intrinsics.height
        edge = np.minimum.reduce(
            [np.abs(u + 0.5), np.abs(u - (w - 0.5)), np.abs(v + 0.5), np.abs(v - (h - 0.5))]
        )
        assert np.all(edge < 1e-3)
        one = ro_client.get(f"/api/sensors/{s['id']}", headers=AUTH).json()
        assert one == s


def test_sensor_image_and_unknown_sensor(ro_client, sample_site_dir):
    site = load_site(sample_site_dir)
    sid = next(k for k, s in site.sensors.items() if s.image_path is not None)
    r = ro_client.get(f"/api/sensors/{sid}/image", headers=AUTH)
    assert r.status_code == 200 and r.content == site.sensors[sid].image_path.read_bytes()
    r = ro_client.get("/api/sensors/nope", headers=AUTH)
    assert r.status_code == 404 and "cam1" in r.json()["detail"]
    for bad in ("/api/sensors/..%2Fsite.json/image", "/api/sensors/../../etc/passwd"):
        assert ro_client.get(bad, headers=AUTH).status_code == 404
