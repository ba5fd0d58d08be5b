"""Measurement models: which terrain hits of a fix count as measurements of the object.

A ray may meet the terrain model several times (a tree crown, then the road, then a
slope behind), nearest first. The families differ only in what they read out:

- :class:`FirstHit`: the nearest hit (the naive answer; it "jumps into trees").
- :class:`LastHit`: the farthest hit (the VSAM paper's foliage heuristic).
- :class:`AllHits`: every hit; the hypothesiser picks the one nearest the prediction.
- :class:`HitMixture`: every hit, used together as a mixture (particles, PDA).
- :class:`RoadHit`: the road rule's hit when there is one, else a :class:`HitMixture`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .protocols import Candidates
from .types import Fix

__all__ = ["AllHits", "FirstHit", "HitMixture", "LastHit", "RoadHit"]


def _cands(
    z: np.ndarray, sigma: np.ndarray, mixture: bool, cov: np.ndarray | None = None
) -> Candidates:
    m = z.shape[0]
    return Candidates(
        z_enu=np.asarray(z, dtype=np.float64).reshape(m, 3),
        sigma_m=np.asarray(sigma, dtype=np.float64).reshape(m),
        weight=np.full(m, 1.0 / m),
        mixture=mixture,
        cov_m2=None if cov is None else np.asarray(cov, dtype=np.float64).reshape(m, 2, 2),
    )


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
    """

    sigma_m: float | None = None

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
        return _cands(fix.road_hit_enu[None, :], np.array([sigma]), mixture=False)
