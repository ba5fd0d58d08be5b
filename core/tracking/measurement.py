"""Measurement models: which terrain hits of a fix count as measurements of the object.

A ray may meet the terrain model several times (a tree crown, then the road, then a
slope behind), nearest first. The families differ only in what they read out:

- :class:`FirstHit`: the nearest hit (the naive answer; it "jumps into trees").
- :class:`LastHit`: the farthest hit (the VSAM paper's foliage heuristic).
- :class:`AllHits`: every hit; the hypothesiser picks the one nearest the prediction.
- :class:`HitMixture`: every hit, used together as a mixture (particles, PDA).
- :class:`RoadHit`: the road rule's hit when there is one, else a :class:`HitMixture`;
  with the road network, the rule's centreline point and the two lanes' centres along
  the ray (a mixture), since vehicles mostly drive beside the centreline.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .protocols import Candidates
from .roads import RoadGraph
from .types import Fix

__all__ = ["AllHits", "FirstHit", "HitMixture", "LastHit", "RoadHit"]


def _cands(
    z: np.ndarray, sigma: np.ndarray, mixture: bool, cov: np.ndarray | None = None
) -> Candidates:
    m = z.shape[0]
    return Candidates._trusted(
        np.asarray(z, dtype=np.float64).reshape(m, 3),
        np.asarray(sigma, dtype=np.float64).reshape(m),
        _uniform(m),
        mixture,
        None if cov is None else np.asarray(cov, dtype=np.float64).reshape(m, 2, 2),
    )


@functools.lru_cache(maxsize=64)
def _uniform(m: int) -> np.ndarray:
    """Equal weights ``1/m`` (m,), read-only and shared (a fix has a handful of hits)."""
    w = np.full(m, 1.0 / m)
    w.setflags(write=False)
    return w


def _covs(fix: Fix, index: slice) -> np.ndarray | None:
    """The fix's full hit covariances at ``index`` (None when it has only sigmas)."""
    return None if fix.hit_cov_en_m2 is None else fix.hit_cov_en_m2[index]


@dataclass(frozen=True)
class FirstHit:
    """The nearest hit only."""

    def candidates(self, fix: Fix) -> Candidates | None:
        """Return the first hit of ``fix``; None without hits."""
        if fix.n_hits == 0:
            return None
        return _cands(fix.hits_enu[:1], fix.hit_sigma_m[:1], False, _covs(fix, slice(0, 1)))


@dataclass(frozen=True)
class LastHit:
    """The farthest hit only (the paper's foliage heuristic)."""

    def candidates(self, fix: Fix) -> Candidates | None:
        """Return the last hit of ``fix``; None without hits."""
        if fix.n_hits == 0:
            return None
        return _cands(fix.hits_enu[-1:], fix.hit_sigma_m[-1:], False, _covs(fix, slice(-1, None)))


@dataclass(frozen=True)
class AllHits:
    """Every hit; the update uses the one the hypothesiser chose (nearest in the gate)."""

    def candidates(self, fix: Fix) -> Candidates | None:
        """All hits of ``fix``; None without hits."""
        if fix.n_hits == 0:
            return None
        return _cands(fix.hits_enu, fix.hit_sigma_m, False, _covs(fix, slice(None)))


@dataclass(frozen=True)
class HitMixture:
    """Every hit, equally likely a priori; the update weighs them all."""

    def candidates(self, fix: Fix) -> Candidates | None:
        """All hits of ``fix`` as a mixture; None without hits."""
        if fix.n_hits == 0:
            return None
        return _cands(fix.hits_enu, fix.hit_sigma_m, True, _covs(fix, slice(None)))


@dataclass(frozen=True)
class RoadHit:
    """The road rule's hit when the fix has one, else every hit as a mixture.

    Parameters
    ----------
    sigma_m : float or None
        Sigma of the road hit (m); None uses the fix's smallest hit sigma (1 m if the fix
        has no other hit).
    network : RoadGraph or None
        The roads the rule used. With it, the rule's point (where the ray's ground track
        crosses a centreline) becomes a mixture of three candidates: itself (a one-lane
        road) and where the ray crosses each lane's centre ``lane_offset_m`` either side,
        ``lane_offset_m / sin(a)`` along the ray (``a``: the angle between the ray's
        ground track and the road). Each is uncertain
        along the ray by ``lane_sigma_m / sin(a)`` more, capped at the fix's own
        along-ray sigma (a ray running along the road says little about where on it).
    lane_offset_m : float
        Distance of a lane's centre from the centreline (m).
    lane_sigma_m : float
        1-sigma of a vehicle's lateral position about its lane's centre (m).
    """

    sigma_m: float | None = None
    network: RoadGraph | None = None
    lane_offset_m: float = 1.5
    lane_sigma_m: float = 0.5

    def candidates(self, fix: Fix) -> Candidates | None:
        """Return the road hit, or all hits as a mixture; None when there is neither."""
        if fix.road_hit_enu is None:
            return HitMixture().candidates(fix)
        if self.sigma_m is not None:
            sigma = self.sigma_m
        elif fix.n_hits:
            sigma = float(fix.hit_sigma_m.min())
        else:
            sigma = 1.0
        if self.network is None:
            return _cands(fix.road_hit_enu[None, :], np.array([sigma]), mixture=False)
        return self._lanes(fix, sigma, self.network)

    def _lanes(self, fix: Fix, sigma: float, network: RoadGraph) -> Candidates:
        """The centre and lane-centre candidates of the fix's road hit (see the class doc)."""
        g = fix.direction_enu[:2]
        g_norm = float(np.hypot(g[0], g[1]))
        road = np.asarray(fix.road_hit_enu, dtype=np.float64)
        if g_norm < 1e-9:
            return _cands(road[None, :], np.array([sigma]), mixture=False)
        g = g / g_norm
        edge, s_m, _ = network.snap(road[None, :2])
        _, normal = network.frame(edge, s_m)
        sin_a = max(abs(float(g @ normal[0])), 1e-3)  # |sin| of the ray-road angle
        # the fix's own along-ray spread bounds what the road can add
        along_max = sigma
        if fix.n_hits:
            along_max = max(float(np.sqrt(g @ fix.hit_covariances()[0] @ g)), sigma)
        shift = min(self.lane_offset_m / sin_a, 3.0 * along_max)
        extra = min(self.lane_sigma_m / sin_a, along_max)
        cov = sigma**2 * np.eye(2) + extra**2 * np.outer(g, g)
        z = np.stack([road, road, road])
        z[0, :2] -= shift * g
        z[2, :2] += shift * g
        sigmas = np.full(3, float(np.sqrt(sigma**2 + extra**2)))
        return _cands(z, sigmas, True, np.stack([cov, cov, cov]))
