"""Shared check of the ray-casting tests: two casts gave the same answers, bit for bit."""

from __future__ import annotations

import numpy as np

from demtrack.core.raycast.hits import RayHits

#: Every per-ray and per-hit array of a :class:`RayHits`.
HIT_FIELDS = ("offsets", "range_m", "points", "status", "crossed_nodata", "truncated")


def assert_identical_hits(a: RayHits, b: RayHits) -> None:
    """Each field of ``a`` and ``b``: same dtype, shape and values (NaN equal to NaN)."""
    for name in HIT_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        np.testing.assert_array_equal(x, y, err_msg=name)
