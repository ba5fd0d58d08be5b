"""LocalFrame against an independent numpy twin, published values and round trips."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod, Transformer

from demtrack.core.errors import CrsError, GeodesyError
from demtrack.core.geo.geodesy import (
    LocalFrame,
    horizontal_crs,
    meridian_convergence_deg,
    scale_factor,
    z_unit_m_of,
)

# ---------------------------------------------------------------- independent reference twin
# Closed-form geodetic -> ECEF (e.g. Hofmann-Wellenhof et al., "GNSS", eq. 10.1; EPSG
# Guidance Note 7-2 method 9602) and the ECEF -> ENU rotation (EPSG method 9836 /
# GeographicLib LocalCartesian), written here from the WGS84 defining constants
# (NIMA TR8350.2: a = 6378137 m, 1/f = 298.257223563). No pyproj involved.
A = 6378137.0
F = 1.0 / 298.257223563
E2 = F * (2.0 - F)
B = A * (1.0 - F)  # 6356752.314245... m, TR8350.2 table 3.3


def twin_ecef(lat_deg, lon_deg, h_m):
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = A / np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h_m) * np.cos(lat) * np.cos(lon),
            (n + h_m) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - E2) + h_m) * np.sin(lat),
        ]
    )


def twin_enu(anchor, lat_deg, lon_deg, h_m):
    lat_deg, lon_deg, h_m = np.broadcast_arrays(
        *(np.asarray(v, dtype=float) for v in (lat_deg, lon_deg, h_m))
    )
    p, lam = np.radians(anchor[0]), np.radians(anchor[1])
    r = np.array(
        [
            [-np.sin(lam), np.cos(lam), 0.0],
            [-np.sin(p) * np.cos(lam), -np.sin(p) * np.sin(lam), np.cos(p)],
            [np.cos(p) * np.cos(lam), np.cos(p) * np.sin(lam), np.sin(p)],
        ]
    )
    d = twin_ecef(lat_deg, lon_deg, h_m) - twin_ecef(*anchor).reshape((3,) + (1,) * lat_deg.ndim)
    return np.tensordot(r, d, axes=1)


BUSHY_RUN = (40.3573, -79.6208, 300.0)

ANCHORS = [
    BUSHY_RUN,
    (0.0, 0.0, 0.0),
    (-33.9, 18.4, 50.0),
    (40.0, 179.999, 10.0),  # antimeridian
    (89.9999, 30.0, 2800.0),  # near the north pole
    (90.0, 0.0, 0.0),  # exactly at the poles
    (-90.0, 45.0, 2800.0),
]


def _points_around(anchor, rng, n=500, span_deg=0.02):
    lat = np.clip(anchor[0] + rng.uniform(-span_deg, span_deg, n), -90.0, 90.0)
    lon = anchor[1] + rng.uniform(-span_deg, span_deg, n) / max(np.cos(np.radians(lat)).min(), 1e-3)
    lon = (lon + 180.0) % 360.0 - 180.0
    h = anchor[2] + rng.uniform(-500.0, 1500.0, n)
    return lat, lon, h


@pytest.mark.parametrize("anchor", ANCHORS)
def test_to_enu_matches_twin(anchor):
    rng = np.random.default_rng(0)
    lat, lon, h = _points_around(anchor, rng)
    frame = LocalFrame(*anchor)
    e, n, u = frame.to_enu(lat, lon, h)
    ref = twin_enu(anchor, lat, lon, h)
    assert np.max(np.abs(np.stack([e, n, u]) - ref)) < 1e-3
    # Far tighter in fact: PROJ and the twin use the same closed form.
    assert np.max(np.abs(np.stack([e, n, u]) - ref)) < 1e-6


@pytest.mark.parametrize("anchor", ANCHORS)
def test_to_geodetic_inverts_to_enu(anchor):
    rng = np.random.default_rng(1)
    lat, lon, h = _points_around(anchor, rng)
    frame = LocalFrame(*anchor)
    enu = np.stack(frame.to_enu(lat, lon, h))
    lat2, lon2, h2 = frame.to_geodetic(*enu)
    # Compare positions in metres through the twin (longitude is arbitrary on the axis).
    back = twin_enu(anchor, lat2, lon2, h2)
    assert np.max(np.abs(back - enu)) < 1e-6
    assert np.max(np.abs(h2 - h)) < 1e-6


def test_antimeridian_anchor():
    anchor = (40.0, 179.999, 10.0)
    frame = LocalFrame(*anchor)
    lat = np.array([40.0, 40.001, 39.999])
    lon = np.array([-179.999, -179.999, -179.9995])
    e, n, u = frame.to_enu(lat, lon, 12.0)
    ref = twin_enu(anchor, lat, lon, 12.0)
    assert np.max(np.abs(np.stack([e, n, u]) - ref)) < 1e-3
    # 0.002 deg of longitude at 40 N is ~170 m east, not ~30000 km west.
    assert 160.0 < e[0] < 180.0
    lat2, lon2, h2 = frame.to_geodetic(e, n, u)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)
    np.testing.assert_allclose(h2, 12.0, atol=1e-6)


@pytest.mark.parametrize("pole", [90.0, -90.0])
def test_exact_pole_points_ignore_longitude(pole):
    frame = LocalFrame(np.sign(pole) * 89.9999, 30.0, 0.0)
    pts = np.stack(frame.to_enu(pole, np.array([-180.0, -45.0, 0.0, 123.0, 180.0]), 5.0))
    assert np.max(np.abs(pts - pts[:, :1])) < 1e-6
    ref = twin_enu((np.sign(pole) * 89.9999, 30.0, 0.0), pole, 0.0, 5.0)
    assert np.max(np.abs(pts[:, 0] - ref)) < 1e-3
    # ~11.17 m from +-89.9999 to the pole, straight along the anchor's north (south).
    assert abs(pts[1, 0] - np.sign(pole) * 11.17) < 0.05
    assert abs(pts[0, 0]) < 1e-6


# ---------------------------------------------------------------- published reference values


def _dms(d, m, s):
    return d + m / 60.0 + s / 3600.0


def test_epsg_guidance_note_7_2_geocentric_example():
    # IOGP Publication 373-7-2 (Guidance Note 7-2), "Geographic/geocentric conversions"
    # (EPSG method 9602), WGS 84: 53 48 33.820 N, 2 07 46.380 E, h = 73.000 m
    # -> X = 3771793.968, Y = 140253.342, Z = 5124304.349 m.
    frame = LocalFrame(_dms(53, 48, 33.820), _dms(2, 7, 46.380), 73.0)
    np.testing.assert_allclose(
        frame.origin_ecef, [3771793.968, 140253.342, 5124304.349], rtol=0, atol=1e-3
    )


def test_epsg_guidance_note_7_2_topocentric_example():
    # Same Guidance Note, "Geographic/topocentric conversions" (EPSG method 9837):
    # topocentric origin 55 N, 5 E, h0 = 200 m (WGS 84); the point above has
    # U (east) = -189013.869, V (north) = -128642.040, W (up) = -4220.171 m.
    frame = LocalFrame(55.0, 5.0, 200.0)
    enu = frame.to_enu(_dms(53, 48, 33.820), _dms(2, 7, 46.380), 73.0)
    np.testing.assert_allclose(enu, [-189013.869, -128642.040, -4220.171], rtol=0, atol=1e-3)
    # And method 9836 (geocentric/topocentric), origin given as X0, Y0, Z0.
    np.testing.assert_allclose(
        frame.origin_ecef, [3652755.3058, 319574.6799, 5201547.3536], rtol=0, atol=1e-4
    )
    enu2 = frame.ecef_to_enu(3771793.968, 140253.342, 5124304.349)
    np.testing.assert_allclose(enu2, [-189013.869, -128642.040, -4220.171], rtol=0, atol=1e-3)


def test_geographiclib_cartconvert_examples():
    # GeographicLib CartConvert(1) man page, EXAMPLES, printed to 2 decimals. The figures
    # are truncated, not rounded (the exact local z is 5783.6466, printed 5783.64; the
    # twin above agrees with 5783.6466), so compare to 1 cm.
    #   echo 33.3 44.4 6000 | CartConvert           => 3816209.60 3737108.55 3485109.57
    #   echo 33.3 44.4 6000 | CartConvert -l 33 44 20 => 37288.97 33374.29 5783.64
    frame = LocalFrame(33.3, 44.4, 6000.0)
    np.testing.assert_allclose(
        frame.origin_ecef, [3816209.60, 3737108.55, 3485109.57], rtol=0, atol=0.01
    )
    local = LocalFrame(33.0, 44.0, 20.0).to_enu(33.3, 44.4, 6000.0)
    np.testing.assert_allclose(local, [37288.97, 33374.29, 5783.64], rtol=0, atol=0.01)


@pytest.mark.parametrize(
    "lat, lon, h, xyz",
    [
        (0.0, 0.0, 0.0, (A, 0.0, 0.0)),
        (0.0, 90.0, 0.0, (0.0, A, 0.0)),
        (0.0, 180.0, 100.0, (-(A + 100.0), 0.0, 0.0)),
        (90.0, 17.0, 0.0, (0.0, 0.0, 6356752.314245)),  # semi-minor axis b
        (-90.0, 0.0, 10.0, (0.0, 0.0, -6356762.314245)),
    ],
)
def test_hand_verified_ecef(lat, lon, h, xyz):
    assert abs(B - 6356752.314245) < 1e-6
    np.testing.assert_allclose(LocalFrame(lat, lon, h).origin_ecef, xyz, rtol=0, atol=1e-6)


def test_curvature_drop_figures():
    # Tangent plane vs the ellipsoid: ~d^2 / 2R: 7 mm at 300 m, 8 cm at 1 km.
    frame = LocalFrame(*BUSHY_RUN)
    _, _, h300 = frame.to_geodetic(300.0, 0.0, 0.0)
    _, _, h1k = frame.to_geodetic(0.0, 1000.0, 0.0)
    assert 0.006 < h300 - 300.0 < 0.008
    assert 0.07 < h1k - 300.0 < 0.09


# ---------------------------------------------------------------- round trips (hypothesis)


@settings(max_examples=150, deadline=None)
@given(
    lat0=st.floats(-90.0, 90.0),
    lon0=st.floats(-180.0, 180.0),
    h0=st.floats(-500.0, 3000.0),
    e=st.floats(-20_000.0, 20_000.0),
    n=st.floats(-20_000.0, 20_000.0),
    u=st.floats(-2_000.0, 2_000.0),
)
def test_roundtrip_enu_geodetic_enu(lat0, lon0, h0, e, n, u):
    frame = LocalFrame(lat0, lon0, h0)
    lat, lon, h = frame.to_geodetic(e, n, u)
    e2, n2, u2 = frame.to_enu(lat, lon, h)
    assert max(abs(e2 - e), abs(n2 - n), abs(u2 - u)) < 1e-6


@settings(max_examples=100, deadline=None)
@given(
    lat0=st.floats(-89.0, 89.0),
    lon0=st.floats(-180.0, 180.0),
    dlat=st.floats(-0.1, 0.1),
    dlon=st.floats(-0.1, 0.1),
    h=st.floats(-400.0, 5000.0),
)
def test_roundtrip_geodetic_enu_geodetic(lat0, lon0, dlat, dlon, h):
    frame = LocalFrame(lat0, lon0, 100.0)
    lat, lon = lat0 + dlat, ((lon0 + dlon + 180.0) % 360.0) - 180.0
    lat2, lon2, h2 = frame.to_geodetic(*frame.to_enu(lat, lon, h))
    assert abs(lat2 - lat) < 1e-10
    assert abs(((lon2 - lon + 180.0) % 360.0) - 180.0) < 1e-10
    assert abs(h2 - h) < 1e-6


# ---------------------------------------------------------------- shapes and validation


def test_scalars_and_broadcasting():
    frame = LocalFrame(*BUSHY_RUN)
    e, n, u = frame.to_enu(40.36, -79.62, 310.0)
    assert np.ndim(e) == 0 and isinstance(e, float)
    e, n, u = frame.to_enu(np.array([[40.36], [40.35]]), np.array([-79.62, -79.63, -79.61]), 310.0)
    assert e.shape == n.shape == u.shape == (2, 3)
    lat, lon, h = frame.to_geodetic(np.zeros((4, 5)), 1.0, 2.0)
    assert lat.shape == (4, 5)
    with pytest.raises(GeodesyError, match="broadcast"):
        frame.to_enu(np.zeros(3), np.zeros(4), 0.0)


@pytest.mark.parametrize(
    "args, match",
    [
        ((91.0, 0.0, 0.0), "latitude"),
        ((-90.5, 0.0, 0.0), "latitude"),
        ((np.nan, 0.0, 0.0), "finite"),
        ((10.0, np.inf, 0.0), "finite"),
        ((10.0, 0.0, np.nan), "finite"),
    ],
)
def test_invalid_inputs(args, match):
    with pytest.raises(GeodesyError, match=match):
        LocalFrame(*args)
    frame = LocalFrame(*BUSHY_RUN)
    with pytest.raises(GeodesyError, match=match) as info:
        frame.to_enu(np.array([40.0, args[0]]), np.array([0.0, args[1]]), args[2])
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)


def test_invalid_enu():
    with pytest.raises(GeodesyError, match="finite"):
        LocalFrame(*BUSHY_RUN).to_geodetic([0.0, np.nan], 0.0, 0.0)


def test_dict_roundtrip_and_errors():
    frame = LocalFrame(*BUSHY_RUN)
    d = json.loads(json.dumps(frame.to_dict()))
    assert d["crs"] == "EPSG:4979"
    assert LocalFrame.from_dict(d) == frame
    assert LocalFrame.from_dict({"lat_deg": 1, "lon_deg": 2, "h_m": 3}) == LocalFrame(1, 2, 3)
    with pytest.raises(GeodesyError, match="missing h_m"):
        LocalFrame.from_dict({"lat_deg": 1.0, "lon_deg": 2.0})
    with pytest.raises(GeodesyError, match="number"):
        LocalFrame.from_dict({"lat_deg": "1", "lon_deg": 2.0, "h_m": 0.0})
    with pytest.raises(GeodesyError, match="EPSG:4979"):
        LocalFrame.from_dict({**d, "crs": "EPSG:4326+5703"})
    with pytest.raises(GeodesyError, match="latitude"):
        LocalFrame.from_dict({**d, "lat_deg": 100.0})


# ---------------------------------------------------------------- other CRSs


def test_to_enu_from_utm_matches_pyproj_plus_twin():
    frame = LocalFrame(*BUSHY_RUN)
    rng = np.random.default_rng(2)
    x = 617114.0 + rng.uniform(-2000, 2000, 200)
    y = 4468328.0 + rng.uniform(-2000, 2000, 200)
    z = rng.uniform(250, 400, 200)
    lon, lat = Transformer.from_crs("EPSG:32617", "EPSG:4326", always_xy=True).transform(x, y)
    ref = twin_enu(BUSHY_RUN, lat, lon, z + 33.5)
    e, n, u = frame.to_enu_from_crs(x, y, z, "EPSG:32617", geoid_undulation_m=33.5)
    assert np.max(np.abs(np.stack([e, n, u]) - ref)) < 1e-3
    x2, y2, z2 = frame.from_enu_to_crs(e, n, u, "EPSG:32617", geoid_undulation_m=33.5)
    assert max(np.abs(x2 - x).max(), np.abs(y2 - y).max(), np.abs(z2 - z).max()) < 1e-6


def test_state_plane_feet_and_compound_heights():
    # NAD83 / Pennsylvania South (ftUS) + NAVD88 height (ftUS): z in US survey feet.
    frame = LocalFrame(*BUSHY_RUN)
    ftus = 1200.0 / 3937.0
    assert z_unit_m_of("EPSG:2272+6360") == pytest.approx(ftus, rel=1e-12)
    assert z_unit_m_of("EPSG:2272") == pytest.approx(ftus, rel=1e-12)  # horizontal unit
    assert z_unit_m_of("EPSG:4326") == 1.0
    assert horizontal_crs("EPSG:2272+6360").to_epsg() == 2272
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:2272", always_xy=True).transform(
        BUSHY_RUN[1], BUSHY_RUN[0]
    )
    z_ft = (300.0 - (-33.0)) / ftus  # orthometric H in ftUS with N = -33 m
    e, n, u = frame.to_enu_from_crs(x, y, z_ft, "EPSG:2272+6360", geoid_undulation_m=-33.0)
    # NAD83 -> WGS84 is PROJ's null transformation here, so the anchor maps to itself.
    assert max(abs(e), abs(n), abs(u)) < 1e-6
    e, n, u = frame.to_enu_from_crs(x + 1000.0, y, z_ft, "EPSG:2272", geoid_undulation_m=-33.0)
    # 1000 ftUS of grid = 1000 ftUS / k on the ellipsoid, times (R + h) / R at h = 333 m.
    ground_m = 1000.0 * ftus / scale_factor("EPSG:2272", *BUSHY_RUN[:2]) * (1 + 333.0 / 6.37e6)
    assert abs(np.hypot(e, n) - ground_m) < 0.003
    assert abs(z_ft * ftus - 333.0) < 1e-9
    # A geographic CRS takes x = longitude.
    e, n, u = frame.to_enu_from_crs(BUSHY_RUN[1], BUSHY_RUN[0], 300.0, "EPSG:4979")
    assert max(abs(e), abs(n), abs(u)) < 1e-6


def test_bad_crs():
    frame = LocalFrame(*BUSHY_RUN)
    with pytest.raises(CrsError, match="no CRS"):
        frame.to_enu_from_crs(0.0, 0.0, 0.0, None)
    with pytest.raises(CrsError, match="unknown CRS"):
        frame.to_enu_from_crs(0.0, 0.0, 0.0, "EPSG:99999999")
    with pytest.raises(CrsError, match="geocentric"):
        frame.to_enu_from_crs(0.0, 0.0, 0.0, "EPSG:4978")
    with pytest.raises(CrsError, match="geographic"):
        scale_factor("EPSG:4326", 40.0, -79.0)


def _true_north_grid_azimuth_deg(crs, lat, lon):
    t = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    x1, y1 = t.transform(lon, lat - 1e-5)
    x2, y2 = t.transform(lon, lat + 1e-5)
    return np.degrees(np.arctan2(x2 - x1, y2 - y1))


@pytest.mark.parametrize(
    "crs, approx_deg",
    [
        # UTM 17N, central meridian -81: gamma ~ (lon - lon0) sin(lat) = +0.894 deg.
        ("EPSG:32617", 1.3792 * np.sin(np.radians(40.3573))),
        # PA South Lambert, central meridian -77.75: gamma = (lon - lon0) sin(phi0) ~ -1.21 deg.
        ("EPSG:2272", None),
    ],
)
def test_meridian_convergence_sign_and_size(crs, approx_deg):
    lat, lon = BUSHY_RUN[:2]
    gamma = meridian_convergence_deg(crs, lat, lon)
    # Definition: grid azimuth = true azimuth - gamma; true north has grid azimuth -gamma.
    assert abs(_true_north_grid_azimuth_deg(crs, lat, lon) + gamma) < 1e-6
    if approx_deg is not None:
        assert abs(gamma - approx_deg) < 0.01
        assert 0.85 < gamma < 0.95
    assert meridian_convergence_deg("EPSG:4326", lat, lon) == 0.0
    g = meridian_convergence_deg(crs, np.array([lat, lat]), lon)
    assert g.shape == (2,)


def test_scale_factor_against_geodesic_distance():
    lat, lon = BUSHY_RUN[:2]
    geod = Geod(ellps="WGS84")
    for crs, unit in [("EPSG:32617", 1.0), ("EPSG:2272", 1200.0 / 3937.0)]:
        t = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
        lon2, lat2, _ = geod.fwd(lon, lat, 90.0, 10.0)  # 10 m along the ellipsoid
        x1, y1 = t.transform(lon, lat)
        x2, y2 = t.transform(lon2, lat2)
        k_num = np.hypot(x2 - x1, y2 - y1) * unit / 10.0
        assert abs(scale_factor(crs, lat, lon) - k_num) < 1e-6
    # UTM: k ~ 0.9996 (1 + (dlon cos lat)^2 / 2) ~ 0.99977 here.
    assert abs(scale_factor("EPSG:32617", lat, lon) - 0.99977) < 1e-5
