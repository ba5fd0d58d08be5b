"""Re-acquisition: does a lost track explain a new track? Identity over long gaps.

When a track has been unseen too long it ends, and the object, seen again, starts a new
tentative track. On confirmation the tracker asks a :class:`Reacquirer` how dense the
lost track's prediction, carried over the absence, is at the new track's position; above
the clutter density the new track takes the old identity (:meth:`Tracker._predecessor`).

- :class:`MotionReacquirer`: the filter's own prediction (its motion model: straight on
  for constant velocity, along the roads for road-constrained particles).
- :class:`RoadFollowingReacquirer`: a vehicle moving near a road is carried along it
  (:func:`.roadfollow.follow_road`) at its last speed, with the spread of the filter's
  prediction along the road (the uncertainty grows with the absence: the gate widens with
  the predicted covariance) and across it at most the lane's; mixed with the plain
  prediction (``p_off_road``) for an object that left the road.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from shapely import LineString

from ..errors import TrackingError
from .kalman import GaussianState
from .particle import ParticleState
from .protocols import Filter
from .roadfollow import follow_road

__all__ = ["MotionReacquirer", "RoadFollowingReacquirer", "gaussian_density", "mean_velocity"]


def gaussian_density(nu_xy: np.ndarray, cov_xy: np.ndarray) -> float:
    """Density (1/m^2) of a 2-D Gaussian with covariance ``cov_xy`` at offset ``nu_xy``."""
    det = float(np.linalg.det(cov_xy))
    if not det > 0:
        return 0.0
    d2 = float(nu_xy @ np.linalg.solve(cov_xy, nu_xy))
    return float(np.exp(-0.5 * d2) / (2.0 * np.pi * math.sqrt(det)))


def mean_velocity(state: object) -> np.ndarray | None:
    """Mean horizontal velocity (2,) (m/s) of a Gaussian or constant-velocity particle state.

    None for states without a planar velocity (raw states, road particles).
    """
    if isinstance(state, GaussianState):
        return state.x[2:4].copy()
    if isinstance(state, ParticleState) and isinstance(state.particles, np.ndarray):
        if state.particles.ndim == 2 and state.particles.shape[1] == 4:
            return state.weights @ state.particles[:, 2:4]
    return None


@dataclass(frozen=True)
class MotionReacquirer:
    """The filter's own prediction over the absence."""

    def density(
        self,
        flt: Filter,
        state: object,
        last_t_s: float,
        last_xy: np.ndarray,
        t_s: float,
        xy: np.ndarray,
        cov_xy: np.ndarray,
        rng: np.random.Generator,
    ) -> float:
        """Predictive density (1/m^2) at ``xy`` (2,) known to ``cov_xy`` (2, 2) at ``t_s``.

        ``state`` is the lost track's (possibly coasted) state; ``last_t_s`` and
        ``last_xy`` (2,) the time and position of its last estimate.
        """
        return float(flt.density(flt.predict(state, t_s, rng), xy, cov_xy))


@dataclass(frozen=True)
class RoadFollowingReacquirer:
    """A lost vehicle follows the road it was on.

    Parameters
    ----------
    lines : sequence of shapely.LineString
        Road centrelines, local frame (m).
    snap_m : float
        A track whose last estimate is farther than this from every road is not on one.
    across_sigma_m : float
        1-sigma across the road of a vehicle that stayed on it (m): the lane, the
        road's half width.
    p_off_road : float
        Weight of the plain (straight-on) prediction in the mixture.
    """

    lines: Sequence[LineString]
    snap_m: float = 5.0
    across_sigma_m: float = 2.0
    p_off_road: float = 0.1

    def __post_init__(self) -> None:
        ok = self.snap_m > 0 and self.across_sigma_m > 0 and 0.0 <= self.p_off_road <= 1.0
        if not ok:
            raise TrackingError(
                "RoadFollowingReacquirer needs snap_m > 0, across_sigma_m > 0, p_off_road in [0, 1]"
            )
        object.__setattr__(self, "lines", tuple(self.lines))

    def predict(
        self, last_xy: np.ndarray, v_xy: np.ndarray, dt_s: float, cov_xy: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Along-road mean (2,) and covariance (2, 2) after ``dt_s``; None off the roads.

        ``cov_xy`` is the plain prediction's covariance: its variance along the road's
        direction at the predicted point is kept, the variance across it is capped at
        ``across_sigma_m**2``.
        """
        times = np.array([dt_s, dt_s + 0.5])
        path = follow_road(self.lines, last_xy, v_xy, times, self.snap_m)
        if path is None:
            return None
        tangent = path[1] - path[0]
        norm = float(np.hypot(tangent[0], tangent[1]))
        if norm < 1e-9:
            return None
        t = tangent / norm
        n = np.array([-t[1], t[0]])
        along = float(t @ cov_xy @ t)
        across = min(float(n @ cov_xy @ n), self.across_sigma_m**2)
        return path[0], along * np.outer(t, t) + across * np.outer(n, n)

    def density(
        self,
        flt: Filter,
        state: object,
        last_t_s: float,
        last_xy: np.ndarray,
        t_s: float,
        xy: np.ndarray,
        cov_xy: np.ndarray,
        rng: np.random.Generator,
    ) -> float:
        """Mixture of the along-road and the plain predictive densities (1/m^2).

        States without a planar velocity (road particles already follow the roads, raw
        states) get the plain prediction only.
        """
        pred = flt.predict(state, t_s, rng)
        plain = float(flt.density(pred, xy, cov_xy))
        v = mean_velocity(state)
        if v is None:
            return plain
        road = self.predict(
            np.asarray(last_xy, dtype=np.float64)[:2], v, t_s - last_t_s, flt.gaussian(pred)[1]
        )
        if road is None:
            return plain
        mean, cov = road
        on_road = gaussian_density(np.asarray(xy, dtype=np.float64) - mean, cov + cov_xy)
        return (1.0 - self.p_off_road) * on_road + self.p_off_road * plain
