"""The terrain surface's numba kernel against its numpy twin: the same bits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.terrain import surface
from demtrack.core.terrain.surface import bilinear_sample, bilinear_sample_reference


def _grid(
    rng: np.random.Generator, nrows: int, ncols: int, dtype: type, holes: float
) -> np.ndarray:
    z = (rng.normal(200.0, 30.0, (nrows, ncols))).astype(dtype)
    z[rng.random((nrows, ncols)) < holes] = np.nan
    return z


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (6, 1), (2, 2), (40, 31)])
def test_kernel_equals_numpy_twin_bit_for_bit(dtype: type, shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(7)
    z = _grid(rng, *shape, dtype, holes=0.1)
    nrows, ncols = shape
    # inside, on the last row/column, just outside, NaN coordinates
    gx = np.r_[rng.uniform(-1.0, ncols, 500), ncols - 1.0, 0.0, -1e-12, ncols - 1 + 1e-9, np.nan]
    gy = np.r_[rng.uniform(-1.0, nrows, 500), nrows - 1.0, 0.0, 0.5, 0.0, 0.0]
    fast = bilinear_sample(z, gx, gy)
    ref = bilinear_sample_reference(z, gx, gy)
    assert fast.dtype == ref.dtype == np.float64
    np.testing.assert_array_equal(fast.view(np.int64), ref.view(np.int64))


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-2.0, 12.0, allow_nan=False),
    y=st.floats(-2.0, 9.0, allow_nan=False),
    seed=st.integers(0, 2**16),
)
def test_kernel_equals_numpy_twin_property(x: float, y: float, seed: int) -> None:
    z = _grid(np.random.default_rng(seed), 8, 11, np.float32, holes=0.05)
    a, b = bilinear_sample(z, x, y), bilinear_sample_reference(z, x, y)
    assert a.shape == b.shape == ()
    assert a.tobytes() == b.tobytes()


def test_shapes_broadcast_and_read_only_inputs() -> None:
    z = np.arange(12.0).reshape(3, 4)
    z.setflags(write=False)
    gx = np.array([[0.5, 1.5, 2.5]])
    gy = np.array([[0.0], [1.0]])
    out = bilinear_sample(z, gx, gy)
    assert out.shape == (2, 3)
    np.testing.assert_array_equal(out, bilinear_sample_reference(z, gx, gy))
    # a plane is reproduced exactly: z = 4 * row + column
    np.testing.assert_allclose(out, 4 * gy + gx)
    assert bilinear_sample(z, np.zeros(0), np.zeros(0)).shape == (0,)


def test_large_calls_take_the_numpy_twin_with_the_same_bits(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rng = np.random.default_rng(3)
    z = _grid(rng, 30, 30, np.float32, holes=0.05)
    gx, gy = rng.uniform(-1, 30, 600), rng.uniform(-1, 30, 600)
    small = bilinear_sample(z, gx, gy)  # the kernel
    monkeypatch.setattr(surface, "KERNEL_MAX_POINTS", 100)
    large = bilinear_sample(z, gx, gy)  # now the numpy form
    assert small.tobytes() == large.tobytes()
