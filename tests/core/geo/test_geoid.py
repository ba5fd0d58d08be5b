"""GeoidModel against an independent reading of the grids, published EGM96 values and users' grids.

The oracle for EGM96 reads ``egm96_15.gtx`` with rasterio (GDAL's GTX driver, not PROJ)
and interpolates bilinearly between grid nodes here, in numpy; the model evaluates the
same grid through PROJ's ``vgridshift``. Published values: NGA's EGM96 test points
(spherical-harmonic synthesis, so the 15' grid differs from them by a few cm) and
Cesium's grid-derived values (0.01 m).
"""

from __future__ import annotations

import numpy as np
import pytest
from geoid_oracle import rasterio_bilinear, write_gtx, write_linear_tif
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.errors import DemtrackError, GeoidError
from demtrack.core.geo.geoid import EGM96_GRID, GeoidModel, as_geoid, find_grid

EGM96_PATH = find_grid(EGM96_GRID)
needs_egm96 = pytest.mark.skipif(EGM96_PATH is None, reason="Debian's proj-data is not installed")


@needs_egm96
def test_egm96_matches_an_independent_bilinear_reading_to_a_millimetre():
    rng = np.random.default_rng(0)
    lat = rng.uniform(-89.5, 89.5, 2000)
    lon = rng.uniform(-180.0, 180.0, 2000)
    # Bushy Run, points on nodes, on the antimeridian and the prime meridian.
    lat = np.concatenate([lat, [40.3556, 40.25, 0.0, 10.1, -45.0]])
    lon = np.concatenate([lon, [-79.6225, -79.5, 0.0, 179.99, -179.99]])
    got = GeoidModel.egm96().undulation_m(lat, lon)
    want = rasterio_bilinear(EGM96_PATH, lat, lon)
    assert np.max(np.abs(got - want)) < 1e-3
    assert np.ptp(want) > 150.0  # the oracle saw the real grid (N spans -105 .. +85 m)


@needs_egm96
@pytest.mark.parametrize(
    ("lat", "lon", "n_m", "tol_m"),
    [
        # Cesium's EGM96 grid test values (0.01 m).
        (0.0, 0.0, 17.16, 0.01),
        (90.0, 0.0, 13.61, 0.01),
        (-90.0, 0.0, -29.53, 0.01),
        (0.0, 180.0, 21.15, 0.01),
        (0.0, -180.0, 21.15, 0.01),
        (-34.75526648786568, 154.6434159812138, 15.53, 0.01),
        # NGA's EGM96 test points (harmonic synthesis; the 15' grid is within 6 cm).
        (38.6281550, 269.7791550, -31.628, 0.06),
        (-14.6212170, 305.0211140, -2.969, 0.06),
        (46.8743190, 102.4487290, -43.575, 0.06),
        (-23.6174460, 133.8747120, 15.871, 0.06),
        (38.6254730, 359.9995000, 50.066, 0.06),
        (-0.4667440, 0.0023000, 17.329, 0.06),
    ],
)
def test_egm96_published_values(lat, lon, n_m, tol_m):
    assert float(GeoidModel.egm96().undulation_m(lat, lon)) == pytest.approx(n_m, abs=tol_m)


@needs_egm96
def test_bushy_run_undulation_and_the_height_round_trip():
    g = GeoidModel.egm96()
    n = float(g.undulation_m(40.3556, -79.6225))
    assert n == pytest.approx(-33.97, abs=0.01)  # the geoid lies 34 m below the ellipsoid
    rng = np.random.default_rng(1)
    lat, lon = rng.uniform(40.3, 40.4, (3, 4)), rng.uniform(-79.7, -79.5, (3, 4))
    h = rng.uniform(300.0, 400.0, (3, 4))
    big_h = g.to_orthometric(lat, lon, h)
    assert big_h.shape == (3, 4)
    assert np.all(big_h - h > 33.0)  # sea-level heights are higher here
    np.testing.assert_allclose(g.to_ellipsoidal(lat, lon, big_h), h, atol=1e-9)
    assert g.orthometric and g.datum == "EGM96 geoid" and "egm96_15.gtx" in g.description


def test_a_user_geotiff_grid_is_bilinear_and_exact_on_a_plane(tmp_path):
    grid = tmp_path / "national_geoid.tif"
    write_linear_tif(grid, -20.0, 0.3, -0.2)
    g = GeoidModel.from_grid(grid, "GEOID-X")
    rng = np.random.default_rng(2)
    lat, lon = rng.uniform(40.21, 40.59, 500), rng.uniform(-79.99, -79.51, 500)
    # Bilinear interpolation reproduces a plane exactly (up to float32 storage).
    np.testing.assert_allclose(g.undulation_m(lat, lon), -20.0 + 0.3 * lon - 0.2 * lat, atol=1e-4)
    np.testing.assert_allclose(
        g.undulation_m(lat, lon), rasterio_bilinear(grid, lat, lon), atol=1e-6
    )
    assert g.datum == "GEOID-X geoid"
    # Off the grid: one clear error naming the grid, never N = 0.
    with pytest.raises(GeoidError, match=r"national_geoid\.tif does not cover 1 point"):
        g.undulation_m([40.3, 45.0], [-79.6, -79.6])


def test_a_hand_written_gtx_grid(tmp_path):
    rng = np.random.default_rng(3)
    n = rng.normal(-30.0, 2.0, (6, 8))
    grid = tmp_path / "local.gtx"
    write_gtx(grid, 40.0, 280.0, 0.1, n)  # lon0 in 0..360, as NOAA writes them
    g = GeoidModel.from_grid(grid)
    assert g.name == "local"
    # A node's value belongs to the node: row 0 is the southern row in .gtx.
    assert float(g.undulation_m(40.0, -80.0)) == pytest.approx(n[0, 0], abs=1e-5)
    assert float(g.undulation_m(40.5, -79.3)) == pytest.approx(n[5, 7], abs=1e-5)
    mid = float(g.undulation_m(40.05, -79.95))
    assert mid == pytest.approx(n[:2, :2].astype(np.float32).mean(), abs=1e-5)
    lat, lon = rng.uniform(40.0, 40.5, 200), rng.uniform(-80.0, -79.3, 200)
    want = rasterio_bilinear(grid, lat, lon)
    np.testing.assert_allclose(g.undulation_m(lat, lon), want, atol=1e-5)


def test_missing_and_unreadable_grids_are_named(tmp_path):
    with pytest.raises(GeoidError, match="geoid grid .*nope.gtx does not exist"):
        GeoidModel.from_grid(tmp_path / "nope.gtx")
    junk = tmp_path / "junk.gtx"
    junk.write_bytes(b"not a grid")
    with pytest.raises(GeoidError, match="PROJ cannot read the geoid grid .*junk.gtx"):
        GeoidModel.from_grid(junk)
    with pytest.raises(GeoidError, match=r"egm96_15\.gtx is not installed .*proj-data") as exc:
        GeoidModel.egm96(dirs=[tmp_path])
    assert isinstance(exc.value, DemtrackError) and isinstance(exc.value, ValueError)
    assert "\n" not in str(exc.value)


def test_constant_and_ellipsoidal_models():
    c = GeoidModel.constant(-33.5)
    np.testing.assert_array_equal(c.undulation_m(np.zeros((2, 3)), 0.0), np.full((2, 3), -33.5))
    assert float(c.to_orthometric(0.0, 0.0, 300.0)) == 333.5
    assert c.datum == "geoid of the site (N = -33.5 m, stated)"
    e = GeoidModel.ellipsoidal()
    assert not e.orthometric and float(e.to_orthometric(10.0, 20.0, 5.0)) == 5.0
    assert as_geoid(0.0) == e and as_geoid(-2.0) == GeoidModel.constant(-2.0)
    assert as_geoid(c) is c
    for bad in (float("nan"), "x"):
        with pytest.raises(GeoidError):
            GeoidModel.constant(bad)  # type: ignore[arg-type]
    with pytest.raises(GeoidError):
        as_geoid(True)  # type: ignore[arg-type]


@needs_egm96
@settings(max_examples=200, deadline=None)
@given(
    lat=st.floats(-90.0, 90.0),
    lon=st.floats(-180.0, 180.0),
    h=st.floats(-500.0, 9000.0),
)
def test_egm96_everywhere_round_trips_and_agrees_with_the_oracle(lat, lon, h):
    g = GeoidModel.egm96()
    n = float(g.undulation_m(lat, lon))
    assert -107.0 < n < 86.0  # EGM96's range on the 15' grid
    assert n == pytest.approx(float(rasterio_bilinear(EGM96_PATH, lat, lon)), abs=1e-3)
    assert float(g.to_ellipsoidal(lat, lon, g.to_orthometric(lat, lon, h))) == pytest.approx(h)
