"""The Kalman kernels against their plain-numpy twins on random states."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.tracking.kalman_kernels import (
    predict_kernel,
    rts_positions_kernel,
    smoother_gain_kernel,
    update_kernel,
)
from demtrack.core.tracking.motion import ConstantVelocity
from demtrack.core.tracking.reference import (
    predict_reference,
    rts_positions_reference,
    smoother_gain_reference,
    update_reference,
)


def _spd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n) * rng.uniform(0.01, 2.0)


@pytest.mark.parametrize("seed", range(10))
def test_kernels_equal_the_numpy_twins(seed):
    rng = np.random.default_rng(seed)
    motion = ConstantVelocity(rng.uniform(0.1, 5.0))
    dt = rng.uniform(0.01, 3.0)
    f, q = motion.transition(dt), motion.covariance(dt)  # read-only, as the filter passes them
    x, p = rng.normal(0, 50, 4), _spd(rng, 4)
    for got, ref in zip(predict_kernel(x, p, f, q), predict_reference(x, p, f, q), strict=True):
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    z, r = rng.normal(0, 50, 2), _spd(rng, 2)
    for got, ref in zip(update_kernel(x, p, z, r), update_reference(x, p, z, r), strict=True):
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-10)
    got_p = update_kernel(x, p, z, r)[1]
    assert (got_p == got_p.T).all() and (np.linalg.eigvalsh(got_p) > 0).all()
    np.testing.assert_allclose(
        smoother_gain_kernel(p, f, q), smoother_gain_reference(p, f, q), rtol=1e-10, atol=1e-12
    )
    n = int(rng.integers(2, 8))
    xs = rng.normal(0, 20, (n, 4))
    fs = np.array([motion.transition(rng.uniform(0.05, 1.0)) for _ in range(n - 1)])
    gains = np.array([smoother_gain_reference(_spd(rng, 4), fk, q) for fk in fs])
    np.testing.assert_allclose(
        rts_positions_kernel(xs, fs, gains),
        rts_positions_reference(xs, fs, gains),
        rtol=1e-10,
        atol=1e-10,
    )


def test_a_precise_fix_pulls_the_state_onto_it():
    """Analytic: with R -> 0 the updated position is the measurement, its variance -> 0."""
    x = np.array([0.0, 0.0, 1.0, -1.0])
    p = np.diag([4.0, 9.0, 1.0, 1.0])
    x_new, p_new = update_kernel(x, p, np.array([3.0, -2.0]), 1e-12 * np.eye(2))
    np.testing.assert_allclose(x_new[:2], [3.0, -2.0], atol=1e-9)
    assert p_new[0, 0] < 1e-9 and p_new[1, 1] < 1e-9
    np.testing.assert_allclose(np.diag(p_new)[2:], [1.0, 1.0])  # uncorrelated: velocity kept
