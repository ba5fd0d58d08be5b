"""The real Autzen lidar tile (laspy's sdist): feet, sparse ground, the TIN grid's bar.

Fetched at test time into a cache outside the repository (``autzen_laz`` fixture in
``tests/conftest.py``). The tile: 110,000 points, Oregon state plane (Lambert conformal
conic, NAD83 HARN) in international feet, 26,107 ground points (class 2).
"""

from __future__ import annotations

import numpy as np
from pyproj import CRS, Transformer

from demtrack.bench.lidar_holdout import holdout_comparison
from demtrack.core.terrain.cloud_site import anchor_for_cloud, cloud_crs, select_surface
from demtrack.core.terrain.crs_import import points_to_local
from demtrack.core.terrain.pointcloud import read_point_cloud

FOOT_M = 0.3048


def test_the_tile_is_in_international_feet_and_sparse(autzen_laz):
    cloud = read_point_cloud(autzen_laz)
    crs = cloud_crs(cloud)
    print(f"Autzen: {crs.name}; unit {crs.xy_unit} = {crs.xy_unit_m} m; z unit {crs.z_unit_m} m")
    assert len(cloud) == 110_000
    assert crs.xy_unit == "foot" and crs.xy_unit_m == FOOT_M and crs.z_unit_m == FOOT_M
    assert "Lambert_Conformal_Conic" in crs.name
    ground = select_surface(cloud, "dtm")
    assert len(ground) == 26_107 and (ground.classification == 2).all()
    dsm = select_surface(cloud, "dsm")
    assert len(dsm) == 99_257 and (dsm.return_number == 1).all()


def test_anchor_and_points_convert_exactly_through_pyproj(autzen_laz):
    cloud = read_point_cloud(autzen_laz)
    crs = cloud_crs(cloud)
    ground = select_surface(cloud, "dtm")
    frame = anchor_for_cloud(ground.xyz, crs, geoid_undulation_m=-21.5)
    # Independent: pyproj straight from the file's WKT to WGS84 3-D and ECEF.
    to_geo = Transformer.from_crs(CRS.from_wkt(crs.crs_wkt), "EPSG:4326", always_xy=True)
    x, y, z = ground.xyz.T
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    lon0, lat0 = to_geo.transform(cx, cy)
    assert abs(frame.lat_deg - lat0) < 1e-7 and abs(frame.lon_deg - lon0) < 1e-7
    assert 44.0 < frame.lat_deg < 44.1 and -123.1 < frame.lon_deg < -123.0  # Eugene, OR
    # on the ground: within the height range of the points near the centre
    near = np.hypot(x - cx, y - cy) < 60.0
    h_near = z[near] * FOOT_M - 21.5
    assert h_near.min() <= frame.h_m <= h_near.max()
    e, n, u = points_to_local(x, y, z, crs.crs_wkt, frame, geoid_undulation_m=-21.5)
    lon, lat = to_geo.transform(x, y)
    ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    px, py, pz = ecef.transform(lon, lat, z * FOOT_M - 21.5)
    ox, oy, oz = ecef.transform(frame.lon_deg, frame.lat_deg, frame.h_m)
    d = np.column_stack([px - ox, py - oy, pz - oz])
    back = d @ frame.R_enu_ecef.T
    assert np.max(np.abs(back - np.column_stack([e, n, u]))) < 1e-3
    # the tile is ~360 m x 170 m: 1180 ft x 560 ft
    assert 350 < e.max() - e.min() < 370 and 160 < n.max() - n.min() < 180


def test_held_out_ground_points_tin_grid_no_worse_than_scipys_tin(autzen_laz):
    r = holdout_comparison(autzen_laz, cell_m=1.0, holdout=0.1, seed=0)
    print(
        f"Autzen held-out at 1 m: {r.density_per_m2:.2f} ground points per m^2; holes "
        f"{r.holes_pct_none:.1f} % without TIN, {r.holes_pct_tin:.1f} % with; "
        f"{r.n_valued}/{r.n_inside} held-out points inside the hull valued; RMSE TIN grid "
        f"{100 * r.rmse_tin_m:.2f} cm, scipy TIN {100 * r.rmse_peer_m:.2f} cm, per-cell "
        f"mean {100 * r.rmse_mean_m:.2f} cm on {r.n_valued_mean}"
    )
    assert r.n_held > 2500 and r.n_inside > 0.99 * r.n_held
    assert r.n_valued == r.n_inside  # every held-out point inside the hull has a value
    assert r.rmse_tin_m <= r.rmse_peer_m
    assert 0.3 < r.density_per_m2 < 0.6  # sparse, as the real tile
    assert r.holes_pct_none > 60.0 and r.holes_pct_tin < 15.0
    # the peer is not trivially beaten: both are centimetre-level on this flat tile
    assert 0.03 < r.rmse_peer_m < 0.10
