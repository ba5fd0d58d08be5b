"""Small-batch fast paths give exactly what the general paths give.

Each shortcut skips conversions, broadcasts or a computation that the usual small call
does not need; the oracle is the general path itself (forced by giving lists, or by
computing the skipped value the old way), on random small inputs, bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.errors import GeodesyError
from demtrack.core.geo import geodesy
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.site.folder import load_site
from demtrack.core.terrain.surface import bilinear_sample


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


def _same(a: object, b: object) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("seed", range(20))
def test_to_geodetic_fast_path_equals_the_general_path(seed):
    rng = np.random.default_rng(seed)
    frame = LocalFrame(rng.uniform(-89, 89), rng.uniform(-180, 180), rng.uniform(-50, 3000))
    n = int(rng.integers(0, 9))
    pts = rng.normal(scale=rng.choice([1.0, 300.0, 2e4]), size=(n, 3))
    assert geodesy._same_length_enu(*pts.T) is not None  # the shortcut is taken
    fast = frame.to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2])  # strided column views
    slow = frame.to_geodetic(*(list(c) for c in pts.T))  # lists: the general path
    for a, b in zip(fast, slow, strict=True):
        assert _same(a, b)


def test_to_geodetic_shortcut_declines_what_it_does_not_handle():
    e = np.array([1.0, 2.0])
    assert geodesy._same_length_enu(e, e, e[:1]) is None  # broadcasting: general path
    assert geodesy._same_length_enu(e, e, e.astype(np.float32)) is None
    assert geodesy._same_length_enu(e, e, [1.0, 2.0]) is None
    assert geodesy._same_length_enu(e[:, None], e[:, None], e[:, None]) is None
    frame = LocalFrame(40.0, -79.0, 300.0)
    with pytest.raises(GeodesyError, match="n must be finite; got nan"):
        frame.to_geodetic(e, np.array([1.0, np.nan]), e)  # the general path's message
    lat, lon, h = frame.to_geodetic(e, e, e[:1])  # still broadcasts
    assert lat.shape == lon.shape == h.shape == (2,)


@pytest.mark.parametrize("seed", range(10))
def test_bilinear_sample_fast_path_equals_the_broadcasting_path(seed):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=(7, 9)).astype(np.float32)
    values[rng.integers(0, 7), rng.integers(0, 9)] = np.nan
    n = int(rng.integers(0, 12))
    gx, gy = rng.uniform(-1, 9, n), rng.uniform(-1, 7, n)
    fast = bilinear_sample(values, gx, gy)
    slow = bilinear_sample(values, list(gx), list(gy))
    assert _same(fast, slow)


def test_hit_batch_sigmas_equal_those_of_one_eigenvalue_call(site):
    """Lazy sigmas: the values the batch used to store (one call over hits and roads)."""
    rng = np.random.default_rng(3)
    geo = site.geolocator()
    for trial in range(8):
        views = []
        for sid in sorted(site.sensors)[: 1 + trial % 3]:
            cam = site.sensors[sid].camera
            w, h = cam.intrinsics.width, cam.intrinsics.height
            k = int(rng.integers(1, 5))
            views.append((cam, rng.uniform(0, w - 1, k), rng.uniform(h / 3, h - 1, k)))
        batch = geo.locate_pixels(views)
        rays = np.flatnonzero(batch.has_road)
        cov = np.concatenate([batch.cov_en_m2, batch.road_cov_en_m2[rays]])
        sigma = np.sqrt(np.linalg.eigvalsh(cov)[:, -1]) if len(cov) else np.zeros(0)
        m = len(batch.range_m)
        road = np.full(batch.n_rays, np.nan)
        road[rays] = sigma[m:]
        assert _same(batch.sigma_m, sigma[:m])
        assert _same(batch.road_sigma_m, road)
