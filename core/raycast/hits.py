"""The answer of a cast: per-ray status and every crossing, in CSR layout.

:class:`RayStatus` mirrors the status codes of the kernels (``core.raycast._walk_kernels``);
:class:`RayHits` holds a batch's hits, read-only.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..errors import RaycastError
from . import _walk_kernels as _k

__all__ = ["BELOW_GROUND", "HIT", "MISS", "OUTSIDE", "UPWARD", "RayHits", "RayStatus"]


class RayStatus(IntEnum):
    """Outcome of one ray (stored as int8 in :attr:`RayHits.status`)."""

    HIT = _k.HIT
    MISS = _k.MISS
    UPWARD = _k.UPWARD
    BELOW_GROUND = _k.BELOW_GROUND
    OUTSIDE = _k.OUTSIDE


HIT = RayStatus.HIT
MISS = RayStatus.MISS
UPWARD = RayStatus.UPWARD
BELOW_GROUND = RayStatus.BELOW_GROUND
OUTSIDE = RayStatus.OUTSIDE


@dataclass(frozen=True, eq=False)
class RayHits:
    """All surface crossings of a batch of rays, in CSR layout.

    Parameters
    ----------
    offsets : ndarray, int64, shape (n + 1,)
        Hits of ray ``i`` are rows ``offsets[i]:offsets[i+1]`` of ``range_m``/``points``.
    range_m : ndarray, float64, shape (m,)
        Distance (m) from the ray origin along the unit direction, increasing per ray.
    points : ndarray, float64, shape (m, 3)
        Crossing points in the DEM's local frame (x east, y north, z up; m).
    status : ndarray, int8, shape (n,)
        :class:`RayStatus` per ray.
    crossed_nodata : ndarray, bool, shape (n,)
        The ray passed over or through a hole, so a crossing may be missing.
    truncated : ndarray, bool, shape (n,)
        The ray had more crossings than ``max_hits``.
    """

    offsets: np.ndarray
    range_m: np.ndarray
    points: np.ndarray
    status: np.ndarray
    crossed_nodata: np.ndarray
    truncated: np.ndarray

    def __post_init__(self) -> None:
        for name in ("offsets", "range_m", "points", "status", "crossed_nodata", "truncated"):
            getattr(self, name).setflags(write=False)

    @property
    def n_rays(self) -> int:
        """Number of rays ``n``."""
        return int(len(self.status))

    @property
    def counts(self) -> np.ndarray:
        """Number of hits per ray, int64 shape (n,)."""
        return np.diff(self.offsets)

    @property
    def hit(self) -> np.ndarray:
        """Boolean mask of rays with at least one hit, shape (n,)."""
        return self.status == HIT

    def first_range_m(self) -> np.ndarray:
        """Range (m) of each ray's nearest hit, NaN where none; shape (n,)."""
        out = np.full(self.n_rays, np.nan)
        has = self.counts > 0
        out[has] = self.range_m[self.offsets[:-1][has]]
        return out

    def first_points(self) -> np.ndarray:
        """Each ray's nearest hit point (local frame, m), NaN rows where none; (n, 3)."""
        out = np.full((self.n_rays, 3), np.nan)
        has = self.counts > 0
        out[has] = self.points[self.offsets[:-1][has]]
        return out

    def hits_of(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Ranges (k,) and points (k, 3) of ray ``i``'s hits, nearest first."""
        if not -self.n_rays <= i < self.n_rays:
            raise RaycastError(f"ray index {i} out of range for {self.n_rays} rays")
        i %= self.n_rays
        lo, hi = int(self.offsets[i]), int(self.offsets[i + 1])
        return self.range_m[lo:hi], self.points[lo:hi]
