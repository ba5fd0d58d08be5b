from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CameraError, DemtrackError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geolocation.geolocate import RULES, Geolocation, Geolocator, GroundHit
from demtrack.core.geolocation.roads import RoadNetwork
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

FRAME = LocalFrame(40.4433, -79.9436, 290.0)  # CMU, Pittsburgh: the paper's site
INTR = Intrinsics(fx=800.0, fy=790.0, cx=319.5, cy=239.5, width=640, height=480)
CENTRE = (319.5, 239.5)
BOTTOM_LEFT = (-0.5, 479.5)  # the outer corner of the image
BOTTOM_RIGHT = (639.5, 479.5)

# Tilted plane z = A x + B y + C: the bilinear surface reproduces it exactly.
A, B, C = 0.02, 0.03, 1.0


def plane_dem(variance_m2: float = 0.0) -> Dem:
    grid = GridSpec.covering(-150.0, -10.0, 150.0, 300.0, 2.0)
    x, y = grid.centres()
    elev = (A * x + B * y + C).astype(np.float32)
    return Dem(grid, elev, variance=np.full(grid.shape, variance_m2, np.float32))


def plane_camera(intr: Intrinsics = INTR) -> Camera:
    return Camera.from_azimuth_tilt_roll(intr, [5.0, 0.0, 40.0], 10.0, -25.0, 2.0)


def analytic_plane_hit(camera: Camera, u: float, v: float) -> tuple[float, np.ndarray]:
    """Hit of pixel (u, v) on the plane, from K and R alone (pinhole)."""
    intr = camera.intrinsics
    d_cam = np.array([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, 1.0])
    d = camera.R_world_cam @ d_cam
    d /= np.linalg.norm(d)
    o = camera.position_enu
    lam = (A * o[0] + B * o[1] + C - o[2]) / (d[2] - A * d[0] - B * d[1])
    return lam, o + lam * d


# Flat ground with a "tree": a block of cells 8 m tall between y = 40 and y = 50.
def tree_dem() -> Dem:
    grid = GridSpec.covering(-30.0, -5.0, 30.0, 120.0, 1.0)
    x, y = grid.centres()
    elev = np.zeros(grid.shape, np.float32)
    elev[(np.abs(x) < 10) & (y > 40) & (y < 50)] = 8.0
    return Dem(grid, elev)


def tree_camera(tilt_deg: float | None = None) -> Camera:
    # From 20 m the centre ray descends 12 m in 45 m: it lands on the tree top at y = 45
    # and, continuing through the crown, on the ground behind it at y = 75.
    tilt = -np.degrees(np.arctan2(12.0, 45.0)) if tilt_deg is None else tilt_deg
    return Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 20.0], 0.0, tilt)


TREE_TOP = np.array([0.0, 45.0, 8.0])
GROUND_BEHIND = np.array([0.0, 75.0, 0.0])


# ------------------------------------------------------------------------- plane


@pytest.mark.parametrize("pixel", [CENTRE, BOTTOM_LEFT, BOTTOM_RIGHT, (100.25, 333.75)])
def test_plane_hit_is_the_analytic_intersection_with_its_geodetic_position(pixel):
    camera = plane_camera()
    geo = Geolocator(plane_dem(), FRAME)
    (loc,) = geo.geolocate(camera, [pixel[0]], [pixel[1]])
    lam, p = analytic_plane_hit(camera, *pixel)
    assert isinstance(loc, Geolocation)
    assert loc.status == "hit" and loc.rule == "first" and (loc.u, loc.v) == pixel
    assert len(loc.hits) == 1 and loc.selected == loc.hits and loc.best is loc.hits[0]
    hit = loc.best
    assert isinstance(hit, GroundHit) and hit.source == "terrain"
    np.testing.assert_allclose(hit.p_enu, p, rtol=0, atol=1e-3)
    assert hit.range_m == pytest.approx(lam, abs=1e-3)
    np.testing.assert_allclose(loc.origin_enu, camera.position_enu)
    np.testing.assert_allclose(loc.direction_enu, (p - camera.position_enu) / lam, atol=1e-9)
    lat, lon, h = FRAME.to_geodetic(*hit.p_enu)
    assert (hit.lat_deg, hit.lon_deg, hit.h_m) == (lat, lon, h)
    # And the geodetic position leads back to the site-frame point.
    np.testing.assert_allclose(FRAME.to_enu(hit.lat_deg, hit.lon_deg, hit.h_m), p, atol=1e-3)
    assert not loc.crossed_nodata
    d = hit.to_dict()
    assert (d["e_m"], d["n_m"], d["u_m"]) == tuple(float(c) for c in hit.p_enu)
    assert d["source"] == "terrain" and d["lat_deg"] == hit.lat_deg


def test_many_pixels_in_one_call_keep_their_order():
    camera = plane_camera()
    u = np.array([CENTRE[0], BOTTOM_LEFT[0], BOTTOM_RIGHT[0]])
    v = np.array([CENTRE[1], BOTTOM_LEFT[1], BOTTOM_RIGHT[1]])
    locs = Geolocator(plane_dem(), FRAME).geolocate(camera, u, v, rule="last")
    assert [(loc.u, loc.v) for loc in locs] == list(zip(u, v, strict=True))
    for loc in locs:
        np.testing.assert_allclose(
            loc.best.p_enu, analytic_plane_hit(camera, loc.u, loc.v)[1], atol=1e-3
        )
    # A scalar pixel is one pixel.
    (one,) = Geolocator(plane_dem(), FRAME).geolocate(camera, CENTRE[0], CENTRE[1])
    np.testing.assert_allclose(one.best.p_enu, locs[0].best.p_enu)


@pytest.mark.parametrize(
    "intr",
    [INTR, Intrinsics(800.0, 790.0, 322.0, 236.0, 640, 480, k1=-0.12, k2=0.03, p1=1e-3, p2=-5e-4)],
    ids=["pinhole", "distorted"],
)
def test_projecting_a_hit_gives_back_its_pixel(intr):
    camera = plane_camera(intr)
    rng = np.random.default_rng(0)
    u = np.r_[rng.uniform(-0.5, 639.5, 30), BOTTOM_LEFT[0], BOTTOM_RIGHT[0]]
    v = np.r_[rng.uniform(240.0, 479.5, 30), BOTTOM_LEFT[1], BOTTOM_RIGHT[1]]
    locs = Geolocator(plane_dem(), FRAME).geolocate(camera, u, v)
    pts = np.array([loc.best.p_enu for loc in locs])
    pu, pv, in_front = camera.project(pts)
    assert in_front.all()
    np.testing.assert_allclose(pu, u, atol=1e-6)
    np.testing.assert_allclose(pv, v, atol=1e-6)


# ---------------------------------------------------------------------- the rules


def test_tree_in_front_gives_the_crown_first_and_the_ground_last():
    geo = Geolocator(tree_dem(), FRAME)
    camera = tree_camera()
    (every,) = geo.geolocate(camera, *CENTRE, rule="all")
    assert every.status == "hit" and len(every.hits) >= 2
    assert every.selected == every.hits
    ranges = [h.range_m for h in every.hits]
    assert ranges == sorted(ranges)
    (first,) = geo.geolocate(camera, *CENTRE, rule="first")
    (last,) = geo.geolocate(camera, *CENTRE, rule="last")
    np.testing.assert_allclose(first.best.p_enu, TREE_TOP, atol=1e-3)
    np.testing.assert_allclose(last.best.p_enu, GROUND_BEHIND, atol=1e-3)
    assert first.best.range_m == pytest.approx(np.hypot(45.0, 12.0), abs=1e-3)
    assert last.best.range_m == pytest.approx(np.hypot(75.0, 20.0), abs=1e-3)
    assert len(first.selected) == len(last.selected) == 1
    assert first.road is None  # no roads given


def test_road_rule_finds_the_road_behind_the_tree():
    roads = RoadNetwork.from_coordinates(
        [np.array([[-25.0, 20.0], [25.0, 20.0]]), np.array([[-25.0, 75.0], [25.0, 75.0]])],
        names=["in front", "behind"],
    )
    geo = Geolocator(tree_dem(), FRAME, roads)
    (loc,) = geo.geolocate(tree_camera(), *CENTRE, rule="road")
    assert loc.status == "hit" and len(loc.selected) == 1
    hit = loc.best
    assert hit is loc.road and hit.source == "road"
    np.testing.assert_allclose(hit.p_enu, GROUND_BEHIND, atol=1e-6)
    assert (hit.lat_deg, hit.lon_deg, hit.h_m) == FRAME.to_geodetic(*hit.p_enu)
    assert np.isfinite(hit.sigma_m) and hit.sigma_m > 0
    assert hit.to_dict()["source"] == "road"
    # Other rules still report the road point alongside their own choice.
    (first,) = geo.geolocate(tree_camera(), *CENTRE, rule="first")
    np.testing.assert_allclose(first.road.p_enu, GROUND_BEHIND, atol=1e-6)
    np.testing.assert_allclose(first.best.p_enu, TREE_TOP, atol=1e-3)
    # With the cut-off short of the far road only the near one is left; the ray passes
    # high above it, so it is no answer unless the gap limit is relaxed.
    near = Geolocator(tree_dem(), FRAME, roads, road_cutoff_m=60.0)
    (loc,) = near.geolocate(tree_camera(), *CENTRE, rule="road")
    assert loc.status == "no_road" and loc.best is None
    near = Geolocator(tree_dem(), FRAME, roads, road_cutoff_m=60.0, road_max_gap_m=1e3)
    (loc,) = near.geolocate(tree_camera(), *CENTRE, rule="road")
    np.testing.assert_allclose(loc.best.p_enu, [0.0, 20.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_geolocator_rejects_non_positive_settings(bad):
    with pytest.raises(CameraError, match="road_max_gap_m must be positive"):
        Geolocator(tree_dem(), FRAME, road_max_gap_m=bad)


def test_road_rule_without_a_crossing_or_without_roads_selects_nothing():
    aside = RoadNetwork.from_coordinates([np.array([[15.0, 0.0], [15.0, 110.0]])])
    for roads in (aside, None, RoadNetwork(())):
        (loc,) = Geolocator(tree_dem(), FRAME, roads).geolocate(tree_camera(), *CENTRE, "road")
        assert loc.status == "no_road"
        assert loc.road is None and loc.selected == () and loc.best is None
        assert len(loc.hits) >= 2  # the terrain crossings are still reported


def test_ray_above_the_horizon_is_upward_with_nothing_selected():
    geo = Geolocator(tree_dem(), FRAME)
    for rule in ("first", "last", "all"):
        (loc,) = geo.geolocate(tree_camera(tilt_deg=20.0), *CENTRE, rule=rule)
        assert loc.status == "upward"
        assert loc.hits == () and loc.selected == () and loc.best is None


def test_ray_leaving_the_dem_before_the_ground_is_a_miss():
    # 1 degree down from 20 m reaches the ground ~1.1 km away; the DEM ends at 120 m.
    (loc,) = Geolocator(tree_dem(), FRAME).geolocate(tree_camera(tilt_deg=-1.0), *CENTRE)
    assert loc.status == "miss" and loc.hits == () and loc.best is None


def test_ray_over_a_hole_is_flagged():
    # A hole behind the tree, where the ray is within the terrain's height range.
    dem = tree_dem()
    elev = np.array(dem.elevation)
    _, y = dem.grid.centres()
    elev[(y > 55) & (y < 60)] = np.nan
    geo = Geolocator(Dem(dem.grid, elev), FRAME)
    (loc,) = geo.geolocate(tree_camera(), *CENTRE, rule="last")
    assert loc.crossed_nodata
    np.testing.assert_allclose(loc.best.p_enu, GROUND_BEHIND, atol=1e-3)
    (clear,) = Geolocator(tree_dem(), FRAME).geolocate(tree_camera(), *CENTRE, rule="last")
    assert not clear.crossed_nodata


# ------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "u, v", [(640.0, 100.0), (-0.51, 100.0), (10.0, 480.0), (np.nan, 10.0), (10.0, -1.0)]
)
def test_pixel_outside_the_image_is_a_camera_error(u, v):
    geo = Geolocator(plane_dem(), FRAME)
    with pytest.raises(CameraError, match="outside the 640x480 image") as info:
        geo.geolocate(plane_camera(), [CENTRE[0], u], [CENTRE[1], v])
    msg = str(info.value)
    assert "\n" not in msg and isinstance(info.value, DemtrackError)


def test_image_edges_are_inside():
    locs = Geolocator(plane_dem(), FRAME).geolocate(plane_camera(), [-0.5, 639.5], [479.5, 479.5])
    assert [loc.status for loc in locs] == ["hit", "hit"]


def test_unknown_rule_and_mismatched_pixels_are_camera_errors():
    geo = Geolocator(plane_dem(), FRAME)
    with pytest.raises(CameraError, match="unknown rule 'nearest'") as info:
        geo.geolocate(plane_camera(), *CENTRE, rule="nearest")
    assert all(r in str(info.value) for r in RULES)
    with pytest.raises(CameraError, match="same length"):
        geo.geolocate(plane_camera(), [1.0, 2.0], [3.0])


# -------------------------------------------------------------------- uncertainty


def _fd_covariance(geo, camera, u, v, sigma_px, sigma_z, h_px=0.05, h_z=0.05):
    """Covariance of the hit by central differences of the whole pipeline."""

    def hit(dem_shift=0.0, du=0.0, dv=0.0):
        g = geo
        if dem_shift:
            d = geo.dem
            g = Geolocator(Dem(d.grid, d.elevation + np.float32(dem_shift)), FRAME)
        (loc,) = g.geolocate(camera, [u + du], [v + dv])
        return loc.best.p_enu[:2]

    j_u = (hit(du=h_px) - hit(du=-h_px)) / (2 * h_px)
    j_v = (hit(dv=h_px) - hit(dv=-h_px)) / (2 * h_px)
    j_z = (hit(dem_shift=h_z) - hit(dem_shift=-h_z)) / (2 * h_z)
    return sigma_px**2 * (np.outer(j_u, j_u) + np.outer(j_v, j_v)) + sigma_z**2 * np.outer(j_z, j_z)


@pytest.mark.parametrize(
    "intr",
    [INTR, Intrinsics(800.0, 790.0, 322.0, 236.0, 640, 480, k1=-0.12, k2=0.03, p1=1e-3, p2=-5e-4)],
    ids=["pinhole", "distorted"],
)
@pytest.mark.parametrize("sigma_z", [0.0, 0.3])
@pytest.mark.parametrize("pixel", [CENTRE, (0.0, 479.0), (600.0, 300.0)])
def test_hit_covariance_matches_finite_differences_of_the_pipeline(intr, pixel, sigma_z):
    # Pixel noise sigma_px on u and v independently, DEM height noise sigma_z: the
    # reported covariance must be the linearisation of pixel -> ray -> terrain, off the
    # optical axis and through lens distortion too.
    sigma_px = 1.5
    camera = plane_camera(intr)
    geo = Geolocator(plane_dem(variance_m2=sigma_z**2), FRAME, pixel_sigma_px=sigma_px)
    (loc,) = geo.geolocate(camera, [pixel[0]], [pixel[1]])
    want = _fd_covariance(geo, camera, *pixel, sigma_px, sigma_z)
    got = loc.best.cov_en_m2
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * np.abs(want).max())
    assert loc.best.sigma_m == pytest.approx(np.sqrt(np.linalg.eigvalsh(want)[-1]), rel=1e-4)


def test_uncertainty_grows_towards_the_horizon():
    camera = plane_camera()
    geo = Geolocator(plane_dem(variance_m2=0.04), FRAME)
    rows = [479.5, 400.0, 300.0, 200.0, 150.0]  # from the image bottom up: shallower rays
    locs = geo.geolocate(camera, np.full(len(rows), CENTRE[0]), rows)
    sigmas = [loc.best.sigma_m for loc in locs]
    assert all(b > a for a, b in zip(sigmas, sigmas[1:], strict=False))
