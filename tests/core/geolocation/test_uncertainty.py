from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.geolocation.uncertainty import hit_covariance


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def perpendicular_axes(d: np.ndarray) -> np.ndarray:
    """Two unit axes perpendicular to ``d``: horizontal 'right' and the in-plane 'down'."""
    e1 = unit(np.cross(d, [0.0, 0.0, 1.0]))
    e2 = np.cross(e1, d)
    return np.array([e1, e2])


def plane_hit(o, d, a, b, c):
    """Intersection of the ray o + lam d with z = a x + b y + c; returns (lam, point)."""
    o, d = np.asarray(o), np.asarray(d)
    lam = (a * o[..., 0] + b * o[..., 1] + c - o[..., 2]) / (
        d[..., 2] - a * d[..., 0] - b * d[..., 1]
    )
    return lam, o + lam[..., None] * d


ORIGIN = np.array([12.0, -4.0, 30.0])
DIR = unit([0.3, 1.0, -0.35])
# Three terrain planes the same ray meets: level, tilted towards and away from the camera.
PLANES = [(0.0, 0.0, 0.0), (0.05, -0.08, 1.0), (-0.02, 0.12, -3.0)]


def test_matches_a_monte_carlo_of_perturbed_rays_and_heights():
    rng = np.random.default_rng(0)
    axes = perpendicular_axes(DIR)
    sig = np.array([2e-4, 3e-4])
    sigma_z = np.array([0.3, 0.1, 0.5])
    n = 200_000
    th = rng.normal(0.0, sig, (n, 2))
    dz = rng.normal(0.0, 1.0, n)
    dirs = unit(DIR + th @ axes)  # the ray tipped towards each axis by the drawn angle
    lam0, grad, covs = [], [], []
    for (a, b, c), sz in zip(PLANES, sigma_z, strict=True):
        lam0.append(plane_hit(ORIGIN, DIR, a, b, c)[0])
        grad.append((a, b))
        _, p = plane_hit(ORIGIN[None, :], dirs, a, b, c + sz * dz)
        covs.append(np.cov(p[:, :2].T))
    got = hit_covariance(DIR, np.array(lam0), np.array(grad), axes, sig, sigma_z)
    assert got.shape == (3, 2, 2)
    for g, want in zip(got, covs, strict=True):
        # Monte-Carlo error on 2e5 samples is ~0.3 %; allow a few percent.
        assert np.linalg.norm(g - want) / np.linalg.norm(want) < 0.02
        np.testing.assert_allclose(np.linalg.eigvalsh(g), np.linalg.eigvalsh(want), rtol=0.03)


def test_matches_finite_differences_of_the_exact_intersection():
    axes = perpendicular_axes(DIR)
    sig = np.array([1.5e-3, 0.7e-3])
    sigma_z = np.array([0.25, 0.0, 1.0])
    h = 1e-6
    lam0, grad, want = [], [], []
    for (a, b, c), sz in zip(PLANES, sigma_z, strict=True):
        lam0.append(plane_hit(ORIGIN, DIR, a, b, c)[0])
        grad.append((a, b))
        jac = []
        for e in axes:
            plus = plane_hit(ORIGIN, unit(DIR + h * e), a, b, c)[1][:2]
            minus = plane_hit(ORIGIN, unit(DIR - h * e), a, b, c)[1][:2]
            jac.append((plus - minus) / (2 * h))
        plus = plane_hit(ORIGIN, DIR, a, b, c + h)[1][:2]
        minus = plane_hit(ORIGIN, DIR, a, b, c - h)[1][:2]
        jac.append((plus - minus) / (2 * h))
        jac = np.array(jac).T  # (2, 3): d(east, north) / d(angle1, angle2, height)
        want.append(jac @ np.diag(np.r_[sig, sz] ** 2) @ jac.T)
    got = hit_covariance(DIR, np.array(lam0), np.array(grad), axes, sig, sigma_z)
    np.testing.assert_allclose(got, np.array(want), rtol=1e-5, atol=1e-12)


def test_level_ground_closed_form_and_growth_as_the_ray_grazes():
    # Camera H above level ground, depression delta: a pointing error sigma in the
    # vertical plane moves the hit H sigma / sin^2(delta) along track, one across the
    # track moves it range * sigma = H sigma / sin(delta); a height error sigma_z moves it
    # sigma_z / tan(delta) along track.
    h_m, sigma, sigma_z, az = 20.0, 1e-3, 0.2, np.radians(30.0)
    along_prev = cross_prev = 0.0
    for delta_deg in (60.0, 30.0, 10.0, 5.0, 2.0, 1.0):
        delta = np.radians(delta_deg)
        d = np.array([np.sin(az) * np.cos(delta), np.cos(az) * np.cos(delta), -np.sin(delta)])
        lam = h_m / np.sin(delta)
        axes = perpendicular_axes(d)
        cov = hit_covariance(d, np.array([lam]), np.zeros((1, 2)), axes, [sigma, sigma], [0.0])[0]
        u_along = np.array([np.sin(az), np.cos(az)])
        u_cross = np.array([np.cos(az), -np.sin(az)])
        along = np.sqrt(u_along @ cov @ u_along)
        cross = np.sqrt(u_cross @ cov @ u_cross)
        assert along == pytest.approx(h_m * sigma / np.sin(delta) ** 2, rel=1e-9)
        assert cross == pytest.approx(h_m * sigma / np.sin(delta), rel=1e-9)
        assert abs(u_along @ cov @ u_cross) < 1e-9 * along**2
        assert along > along_prev and cross > cross_prev
        along_prev, cross_prev = along, cross
        cov_z = hit_covariance(d, [lam], np.zeros((1, 2)), np.zeros((0, 3)), [], [sigma_z])[0]
        assert np.sqrt(u_along @ cov_z @ u_along) == pytest.approx(
            sigma_z / np.tan(delta), rel=1e-9
        )
        assert abs(u_cross @ cov_z @ u_cross) < 1e-12 * (u_along @ cov_z @ u_along)


def test_a_level_ray_stays_finite_and_huge():
    d = np.array([0.0, 1.0, 0.0])
    cov = hit_covariance(d, [100.0], np.zeros((1, 2)), perpendicular_axes(d), [1e-3, 1e-3], [0.1])
    assert np.isfinite(cov).all()
    assert np.sqrt(np.linalg.eigvalsh(cov[0])[-1]) > 1e6


def test_zero_noise_gives_zero_covariance_and_empty_hits_an_empty_array():
    cov = hit_covariance(DIR, [50.0], np.zeros((1, 2)), perpendicular_axes(DIR), [0.0, 0.0], [0.0])
    np.testing.assert_array_equal(cov, 0.0)
    empty = hit_covariance(
        DIR, np.zeros(0), np.zeros((0, 2)), perpendicular_axes(DIR), [1.0, 1.0], []
    )
    assert empty.shape == (0, 2, 2)


@settings(max_examples=60, deadline=None)
@given(
    az=st.floats(0.0, 360.0),
    depression=st.floats(0.5, 89.0),
    grad=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)),
    lam=st.floats(1.0, 5000.0),
    sigmas=st.tuples(st.floats(0.0, 1e-2), st.floats(0.0, 1e-2)),
    sigma_z=st.floats(0.0, 5.0),
    spin=st.floats(0.0, 180.0),
)
def test_covariance_is_symmetric_positive_semidefinite(
    az, depression, grad, lam, sigmas, sigma_z, spin
):
    a, e = np.radians(az), np.radians(depression)
    d = np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), -np.sin(e)])
    e1, e2 = perpendicular_axes(d)
    s = np.radians(spin)  # any orthonormal pair perpendicular to the ray
    axes = np.array([np.cos(s) * e1 + np.sin(s) * e2, -np.sin(s) * e1 + np.cos(s) * e2])
    cov = hit_covariance(d, [lam], np.array([grad]), axes, list(sigmas), [sigma_z])[0]
    assert np.isfinite(cov).all()
    np.testing.assert_array_equal(cov, cov.T)
    w = np.linalg.eigvalsh(cov)
    assert w[0] >= -1e-12 * max(w[-1], 1.0)
