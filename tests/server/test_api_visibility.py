"""The visibility endpoints against :func:`demtrack.core.visibility.viewshed.viewshed` itself.

Oracles: the GeoJSON polygons rasterised back (rasterio, cell-centre rule) give exactly
the viewshed mask; the coverage PNG decoded through its legend gives the sensor count per
cell; the coverage JSON's areas and blind spots are the mask counts and ``blind_spots``.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from rasterio.features import rasterize
from scipy import ndimage
from server_helpers import AUTH
from shapely.geometry import shape

from demtrack.core.site.folder import load_site
from demtrack.core.visibility.viewshed import blind_spots, viewshed


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


def _reference(
    site, sid: str, target_height_m: float = 1.7, max_range_m: float = 1000.0
) -> np.ndarray:
    s = site.sensors[sid]
    return viewshed(
        site.dem,
        s.camera,
        mode="fov",
        target_height_m=target_height_m,
        max_range_m=max_range_m,
        mount_yaw_deg=s.head.mount_yaw_deg,
    )


@pytest.fixture(scope="module")
def masks(site):
    return {sid: _reference(site, sid) for sid in sorted(site.sensors)}


def _burn(geometry: dict, grid) -> np.ndarray:
    """Cells whose centre lies inside ``geometry`` (site frame), as a bool raster."""
    if not geometry["coordinates"]:
        return np.zeros(grid.shape, bool)
    out = rasterize([(geometry, 1)], out_shape=grid.shape, transform=grid.transform, fill=0)
    return out.astype(bool)


def test_viewshed_polygons_cover_exactly_the_visible_cells(ro_client, site, masks):
    g = site.dem.grid
    assert len(masks) >= 2 and all(m.any() for m in masks.values())
    for sid, ref in masks.items():
        r = ro_client.get(f"/api/sensors/{sid}/viewshed.geojson?frame=enu", headers=AUTH)
        assert r.status_code == 200, r.text
        doc = r.json()
        assert doc["type"] == "FeatureCollection" and doc["frame"] == "site ENU (m)"
        (feat,) = doc["features"]
        geom = feat["geometry"]
        assert geom["type"] == "MultiPolygon"
        np.testing.assert_array_equal(_burn(geom, g), ref, err_msg=sid)
        props = feat["properties"]
        assert props["sensor"] == sid and props["cells"] == int(ref.sum())
        assert props["area_m2"] == pytest.approx(ref.sum() * g.cell_m**2)
        assert props["target_height_m"] == 1.7 and props["mode"] == "fov"
        multi = shape(geom)
        assert multi.is_valid
        assert multi.area == pytest.approx(props["area_m2"])
        for poly in multi.geoms:  # RFC 7946 winding: exterior counter-clockwise
            assert poly.exterior.is_ccw
            assert not any(hole.is_ccw for hole in poly.interiors)


def test_viewshed_lonlat_is_lon_lat_inside_the_site_and_maps_back(ro_client, site, masks):
    box = ro_client.get("/api/site", headers=AUTH).json()["bounds_lonlat"]
    sid = max(masks, key=lambda k: masks[k].sum())
    r = ro_client.get(f"/api/sensors/{sid}/viewshed.geojson", headers=AUTH)
    assert r.status_code == 200
    (feat,) = r.json()["features"]
    pts = np.array(
        [p for poly in feat["geometry"]["coordinates"] for ring in poly for p in ring], float
    )
    lon, lat = pts[:, 0], pts[:, 1]
    eps = 1e-7
    assert (lon >= box[0] - eps).all() and (lon <= box[2] + eps).all()
    assert (lat >= box[1] - eps).all() and (lat <= box[3] + eps).all()
    # back to the site frame: the same cells
    fr = site.frame
    e, n, _ = fr.to_enu(lat, lon, np.full(len(lat), fr.h_m))
    it = iter(zip(np.asarray(e).tolist(), np.asarray(n).tolist(), strict=True))
    polys = [
        [[list(next(it)) for _ in ring] for ring in poly]
        for poly in feat["geometry"]["coordinates"]
    ]
    back = {"type": "MultiPolygon", "coordinates": polys}
    np.testing.assert_array_equal(_burn(back, site.dem.grid), masks[sid])
    assert "frame" not in r.json()


def test_viewshed_parameters_reach_the_engine_and_the_cache_keeps_them_apart(ro_client, site):
    sid = sorted(site.sensors)[0]
    areas = {}
    for h in (0.0, 6.0, 0.0):
        r = ro_client.get(
            f"/api/sensors/{sid}/viewshed.geojson?frame=enu&target_height_m={h}", headers=AUTH
        )
        ref = _reference(site, sid, h)
        (feat,) = r.json()["features"]
        np.testing.assert_array_equal(_burn(feat["geometry"], site.dem.grid), ref)
        areas[h] = feat["properties"]["area_m2"]
    assert areas[6.0] != areas[0.0]


def test_coverage_png_counts_the_sensors_per_cell(ro_client, site, masks):
    count = np.sum(list(masks.values()), axis=0)
    r = ro_client.get("/api/site/coverage.png", headers=AUTH)
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    img = np.asarray(Image.open(io.BytesIO(r.content)))
    assert img.shape == (*site.dem.grid.shape, 4)
    np.testing.assert_array_equal(img[..., 3] > 0, count >= 1)
    legend = ro_client.get("/api/site/coverage.json", headers=AUTH).json()["legend"]
    decoded = np.zeros(count.shape, int)
    for entry in legend:
        decoded[(img == np.array(entry["rgba"], np.uint8)).all(axis=-1)] = entry["count"]
    np.testing.assert_array_equal(decoded, np.minimum(count, len(legend)))
    assert (count >= 2).any()  # the sample site has overlap: the colours are exercised


def test_coverage_json_matches_viewsheds_and_blind_spots(ro_client, site, masks):
    r = ro_client.get("/api/site/coverage.json?min_area_m2=10&limit=3", headers=AUTH)
    assert r.status_code == 200
    body = r.json()
    cell_area = site.dem.grid.cell_m**2
    got = {s["id"]: s for s in body["sensors"]}
    assert set(got) == set(masks)
    for sid, ref in masks.items():
        assert got[sid]["cells"] == int(ref.sum())
        assert got[sid]["area_m2"] == pytest.approx(ref.sum() * cell_area)
    count = np.sum(list(masks.values()), axis=0)
    data = (~site.dem.nodata).sum()
    assert body["seen_by_at_least"]["1"] == pytest.approx((count >= 1).sum() / data)
    assert body["seen_by_at_least"]["2"] == pytest.approx((count >= 2).sum() / data)
    spots = blind_spots(count, site.dem, min_area_m2=10)
    assert body["blind_spot_count"] == len(spots) > 3
    listed = body["blind_spots"]
    assert len(listed) == 3
    for b, ref_b in zip(listed, spots, strict=False):
        assert b["area_m2"] == pytest.approx(ref_b.area_m2)
        assert b["centroid_enu"] == pytest.approx([ref_b.centroid_e_m, ref_b.centroid_n_m])
    areas = [b["area_m2"] for b in listed]
    assert areas == sorted(areas, reverse=True)
    # the largest blind spot is unseen: its cells count as zero in the png
    lon, lat = listed[0]["centroid_lonlat"]
    e, n, _ = site.frame.to_enu(lat, lon, site.frame.h_m)
    assert e == pytest.approx(listed[0]["centroid_enu"][0], abs=0.01)
    assert n == pytest.approx(listed[0]["centroid_enu"][1], abs=0.01)


@pytest.mark.parametrize("target_height_m, max_range_m", [(1.7, 1000.0), (0.5, 180.0)])
def test_blind_spot_outlines_cover_exactly_the_unseen_cells(
    ro_client, site, masks, target_height_m, max_range_m
):
    g = site.dem.grid
    if (target_height_m, max_range_m) == (1.7, 1000.0):
        ref = masks
    else:
        ref = {sid: _reference(site, sid, target_height_m, max_range_m) for sid in masks}
    unseen = (np.sum(list(ref.values()), axis=0) == 0) & ~site.dem.nodata
    r = ro_client.get(
        "/api/site/coverage.json",
        params={
            "target_height_m": target_height_m,
            "max_range_m": max_range_m,
            "min_area_m2": 0,
            "limit": 10_000,
        },
        headers=AUTH,
    )
    assert r.status_code == 200, r.text
    body = r.json()
    listed = body["blind_spots"]
    assert len(listed) == body["blind_spot_count"] >= 2
    covered = np.zeros(g.shape, bool)
    eight = np.ones((3, 3), bool)
    for b in listed:
        geom = {"type": "MultiPolygon", "coordinates": b["outline_enu"]}
        cells = _burn(geom, g)
        assert not (cells & covered).any()  # the spots are disjoint
        covered |= cells
        assert cells.sum() * g.cell_m**2 == pytest.approx(b["area_m2"])
        # one 8-connected unseen area, with its own centroid and bounding box
        assert ndimage.label(cells, structure=eight)[1] == 1
        rows, cols = np.nonzero(cells)
        x, y = g.from_grid(cols.astype(float), rows.astype(float))
        assert b["centroid_enu"] == pytest.approx([x.mean(), y.mean()])
        half = g.cell_m / 2
        box = [x.min() - half, y.min() - half, x.max() + half, y.max() + half]
        assert b["bbox_enu"] == pytest.approx(box)
        multi = shape(geom)
        assert multi.is_valid and multi.area == pytest.approx(b["area_m2"])
        for poly in multi.geoms:
            assert poly.exterior.is_ccw
    # together they are exactly the cells no sensor sees
    np.testing.assert_array_equal(covered, unseen)


def test_unknown_sensor_is_404(ro_client):
    r = ro_client.get("/api/sensors/nope/viewshed.geojson", headers=AUTH)
    assert r.status_code == 404 and "nope" in r.json()["detail"]


@pytest.mark.parametrize(
    "query",
    [
        "target_height_m=-1",
        "target_height_m=nan",
        "target_height_m=inf",
        "target_height_m=abc",
        "target_height_m=1e9",
        "max_range_m=0",
        "mode=sideways",
        "frame=utm",
    ],
)
def test_bad_viewshed_parameters_are_422(ro_client, site, query):
    sid = sorted(site.sensors)[0]
    r = ro_client.get(f"/api/sensors/{sid}/viewshed.geojson?{query}", headers=AUTH)
    assert r.status_code == 422 and r.json()["detail"]


@pytest.mark.parametrize(
    "path",
    [
        "/api/site/coverage.png?target_height_m=-0.5",
        "/api/site/coverage.json?target_height_m=nan",
        "/api/site/coverage.json?min_area_m2=-1",
        "/api/site/coverage.json?limit=-1",
    ],
)
def test_bad_coverage_parameters_are_422(ro_client, path):
    assert ro_client.get(path, headers=AUTH).status_code == 422


def test_visibility_reads_need_the_token(ro_client, site):
    sid = sorted(site.sensors)[0]
    for path in (
        f"/api/sensors/{sid}/viewshed.geojson",
        "/api/site/coverage.png",
        "/api/site/coverage.json",
    ):
        assert ro_client.get(path).status_code == 401, path
