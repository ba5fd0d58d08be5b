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

__all__ = [
    "MotionReacquirer",
    "RoadFollowingReacquirer",
    "gaussian_density",
    "mean_velocity",
    "velocity_gaussian",
    "velocity_prior_density",
]


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


def velocity_gaussian(state: object) -> tuple[np.ndarray, np.ndarray] | None:
    """Horizontal velocity mean (2,) and covariance (2, 2) (m/s, (m/s)^2) of a state.

    Gaussian states: their velocity block; constant-velocity particles: the weighted
    mean and covariance. None for states without a planar velocity.
    """
    if isinstance(state, GaussianState):
        return state.x[2:4].copy(), state.P[2:4, 2:4].copy()
    if isinstance(state, ParticleState) and isinstance(state.particles, np.ndarray):
        if state.particles.ndim == 2 and state.particles.shape[1] == 4:
            w = state.weights
            v = state.particles[:, 2:4]
            mean = w @ v
            d = v - mean
            return mean, (w[:, None] * d).T @ d
    return None


def velocity_prior_density(v_xy: np.ndarray, cov_v: np.ndarray, speed_sigma_m_s: float) -> float:
    """Density (1/(m/s)^2) a new object's velocity prior gives a velocity estimate.

    The prior is the one a new track starts from: zero mean, ``speed_sigma_m_s`` per
    axis; the estimate ``v_xy`` (2,) is known to ``cov_v`` (2, 2).
    """
    return gaussian_density(
        np.asarray(v_xy, dtype=np.float64), cov_v + speed_sigma_m_s**2 * np.eye(2)
    )


def _velocity_factor(
    pred: tuple[np.ndarray, np.ndarray] | None,
    v_xy: np.ndarray | None,
    cov_v: np.ndarray | None,
) -> float:
    """Predicted velocity's density at the new track's (1 when either is unknown)."""
    if pred is None or v_xy is None or cov_v is None:
        return 1.0
    return gaussian_density(np.asarray(v_xy, dtype=np.float64) - pred[0], pred[1] + cov_v)


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
        v_xy: np.ndarray | None = None,
        cov_v: np.ndarray | None = None,
    ) -> float:
        """Predictive density (1/m^2) at ``xy`` (2,) known to ``cov_xy`` (2, 2) at ``t_s``.

        ``state`` is the lost track's (possibly coasted) state; ``last_t_s`` and
        ``last_xy`` (2,) the time and position of its last estimate. With the new
        track's velocity ``v_xy`` (2,) known to ``cov_v`` (2, 2), the density is joint
        (times that of the predicted velocity there, 1/(m/s)^2) where the predicted
        state has a velocity (:func:`velocity_gaussian`).
        """
        pred = flt.predict(state, t_s, rng)
        plain = float(flt.density(pred, xy, cov_xy))
        return plain * _velocity_factor(velocity_gaussian(pred), v_xy, cov_v)


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
        v_xy: np.ndarray | None = None,
        cov_v: np.ndarray | None = None,
    ) -> float:
        """Mixture of the along-road and the plain predictive densities (1/m^2).

        States without a planar velocity (road particles already follow the roads, raw
        states) get the plain prediction only. With the new track's velocity ``v_xy``
        known to ``cov_v`` each mode is joint over position and velocity (see
        :meth:`MotionReacquirer.density`); along the road the predicted velocity is the
        last speed along the road's direction at the predicted point, with the plain
        prediction's velocity covariance.
        """
        pred = flt.predict(state, t_s, rng)
        pred_v = velocity_gaussian(pred)
        plain = float(flt.density(pred, xy, cov_xy)) * _velocity_factor(pred_v, v_xy, cov_v)
        v = mean_velocity(state)
        if v is None:
            return plain
        dt = t_s - last_t_s
        road = self.predict(np.asarray(last_xy, dtype=np.float64)[:2], v, dt, flt.gaussian(pred)[1])
        if road is None:
            return plain
        mean, cov = road
        on_road = gaussian_density(np.asarray(xy, dtype=np.float64) - mean, cov + cov_xy)
        if pred_v is not None and v_xy is not None:
            times = np.array([dt, dt + 0.5])
            path = follow_road(self.lines, np.asarray(last_xy)[:2], v, times, self.snap_m)
            if path is not None:
                along_v = (path[1] - path[0]) / 0.5
                on_road *= _velocity_factor((along_v, pred_v[1]), v_xy, cov_v)
        return (1.0 - self.p_off_road) * on_road + self.p_off_road * plain
