"""The fusion kernels against their plain-numpy twins, degenerate pairs included."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.tracking.fusion_kernels import screen_pairs_kernel, triangulation_cov_kernel
from demtrack.core.tracking.reference import (
    screen_pairs_reference,
    triangulation_cov_reference,
)


def _side(rng, n, k, min_hits=0):
    """Rays (unit, one vertical), NaN-padded hits (fix 1 without any unless ``min_hits``)."""
    o = rng.uniform(-200, 200, (n, 3))
    d = rng.normal(size=(n, 3))
    d[0] = [0.0, 0.0, -1.0]  # vertical
    d /= np.linalg.norm(d, axis=1)[:, None]
    t = rng.uniform(0, 0.2, n)
    c = rng.integers(0, 2, n).astype(np.int64)
    hx = rng.uniform(-60, 60, (n, k, 2))
    sg = rng.uniform(0.2, 3.0, (n, k))
    a = rng.uniform(0.1, 4.0, (n, k))
    b = rng.uniform(0.1, 4.0, (n, k))
    r = rng.uniform(-0.9, 0.9, (n, k)) * np.sqrt(a * b)
    cv = np.stack([np.stack([a, r], -1), np.stack([r, b], -1)], -2)
    n_hits = rng.integers(min_hits, k + 1, n)
    if min_hits == 0:
        n_hits[1] = 0  # a fix without hits
    for i, m in enumerate(n_hits):
        hx[i, m:] = np.nan
        sg[i, m:] = np.nan
        cv[i, m:] = np.nan
    return o, d, t, c, hx, sg, cv


@pytest.mark.parametrize("seed", range(8))
def test_screen_kernel_equals_the_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    a = _side(rng, 6, 3)
    b = _side(rng, 5, 2)
    b[0][2], b[1][2] = a[0][2], a[1][2]  # b's third ray: a copy of a's, parallel to it
    args = (*a, *b, 0.1, np.sin(np.radians(10.0)), 2.0, 3.0)
    got = screen_pairs_kernel(*args)
    ref = screen_pairs_reference(*args)
    for g, r in zip(got, ref, strict=True):
        assert g.shape == r.shape
        if g.dtype == bool:
            assert (g == r).all()
        else:
            np.testing.assert_allclose(g, r, rtol=1e-9, atol=1e-9, equal_nan=True)
    assert np.isinf(got[2][1]).all()  # no hits: no finite cost
    assert (got[1][:, 1] == -np.inf).all()  # ... and never in the gate


@pytest.mark.parametrize("seed", range(8))
def test_triangulation_kernel_equals_the_numpy_twin(seed):
    rng = np.random.default_rng(100 + seed)
    m, k = 7, 3
    p = rng.uniform(-50, 50, (m, 3))
    miss = rng.uniform(0, 3, m)
    sin_angle = rng.uniform(0.2, 1.0, m)
    ra, rb = rng.uniform(5, 300, m), rng.uniform(5, 300, m)
    ga, gb = rng.normal(size=(m, 2)), rng.normal(size=(m, 2))
    ga[0] = 0.0  # vertical ray on side a
    # matched pairs always have hits on both sides (else their cost is not finite)
    _, _, _, _, hxa, _, cva = _side(rng, m, k, min_hits=1)
    _, _, _, _, hxb, _, cvb = _side(rng, m, k, min_hits=1)
    args = (p, miss, sin_angle, ra, rb, ga, gb, hxa, cva, hxb, cvb, 0.002)
    cov, sigma = triangulation_cov_kernel(*args)
    cov_ref, sigma_ref = triangulation_cov_reference(*args)
    np.testing.assert_allclose(cov, cov_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(sigma, sigma_ref, rtol=1e-9)
    assert (cov[:, 0, 1] == cov[:, 1, 0]).all()
    assert (np.linalg.eigvalsh(cov) > 0).all()
