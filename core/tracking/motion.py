"""Constant-velocity motion in the horizontal plane of the local frame.

State ``[x, y, vx, vy]`` (m, m/s). The acceleration is white noise of spectral density
``q`` (m^2/s^3) per axis, which gives the familiar per-axis process noise::

    Q_axis = q * [[dt^3/3, dt^2/2],
                  [dt^2/2, dt    ]]

Heights are not modelled: a track's ``z`` comes from the terrain hit it used.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import TrackingError
from .protocols import Candidates

__all__ = [
    "ConstantVelocity",
    "ConstantVelocityParticles",
    "allocate_counts",
    "sample_candidates",
]


@dataclass(frozen=True)
class ConstantVelocity:
    """Linear-Gaussian constant-velocity model (the Kalman filter's motion model).

    Parameters
    ----------
    q_m2_s3 : float
        Acceleration noise spectral density per axis (m^2/s^3).
    """

    q_m2_s3: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.q_m2_s3) and self.q_m2_s3 > 0):
            raise TrackingError(f"q_m2_s3 must be positive, got {self.q_m2_s3}")

    def transition(self, dt_s: float) -> np.ndarray:
        """State transition matrix F, shape (4, 4) (read-only; shared between calls)."""
        return _cv_matrices(self.q_m2_s3, float(dt_s))[0]

    def covariance(self, dt_s: float) -> np.ndarray:
        """Process noise covariance Q, shape (4, 4) (read-only; shared between calls)."""
        return _cv_matrices(self.q_m2_s3, float(dt_s))[1]


@functools.lru_cache(maxsize=4096)
def _cv_matrices(q: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of :class:`ConstantVelocity` (each (4, 4), read-only).

    Cached: a tracker predicts every track to each scan's time, and frame-synchronous
    cameras make the same few intervals over and over.
    """
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt_s
    axis = q * np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
    out = np.zeros((4, 4))
    for k in (0, 1):  # x with vx, y with vy
        out[k, k] = axis[0, 0]
        out[k, k + 2] = axis[0, 1]
        out[k + 2, k] = axis[1, 0]
        out[k + 2, k + 2] = axis[1, 1]
    f.setflags(write=False)
    out.setflags(write=False)
    return f, out


def sample_candidates(cands: Candidates, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` horizontal positions (n, 2) drawn around the candidates by their weights.

    Each candidate gets its share of the samples (:func:`allocate_counts`), drawn from
    its Gaussian (its full covariance, elongated along the ray).
    """
    counts = allocate_counts(cands.weight, n)
    chol = np.linalg.cholesky(cands.covariances())
    which = np.repeat(np.arange(cands.size), counts)
    e = rng.standard_normal((n, 2))
    return cands.z_enu[which, :2] + np.einsum("nij,nj->ni", chol[which], e)


def allocate_counts(weight: np.ndarray, n: int) -> np.ndarray:
    """Split ``n`` items over ``weight`` (sums to 1) by largest remainders; shape (m,)."""
    raw = np.asarray(weight, dtype=np.float64) * n
    counts = np.floor(raw).astype(np.int64)
    rest = n - int(counts.sum())
    if rest > 0:
        order = np.argsort(-(raw - counts), kind="stable")
        counts[order[:rest]] += 1
    return counts


@dataclass(frozen=True)
class ConstantVelocityParticles:
    """Constant-velocity motion sampled for a particle set (array of shape (n, 4)).

    Parameters
    ----------
    q_m2_s3 : float
        Acceleration noise spectral density per axis (m^2/s^3).
    init_speed_sigma_m_s : float
        1-sigma of each velocity component of new particles (m/s).
    """

    q_m2_s3: float
    init_speed_sigma_m_s: float

    def initial(self, cands: Candidates, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` particles around the candidates in proportion to their weights."""
        out = np.empty((n, 4))
        out[:, :2] = sample_candidates(cands, n, rng)
        out[:, 2:] = self.init_speed_sigma_m_s * rng.standard_normal((n, 2))
        return out

    def propagate(self, particles: np.ndarray, dt_s: float, rng: np.random.Generator) -> np.ndarray:
        """Move the particles ``dt_s`` ahead; noise drawn from the exact discrete Q."""
        if dt_s <= 0.0:
            return particles
        out = particles.copy()
        out[:, :2] += dt_s * particles[:, 2:]
        axis = self.q_m2_s3 * np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
        chol = np.linalg.cholesky(axis)
        n = particles.shape[0]
        for k in (0, 1):
            noise = rng.standard_normal((n, 2)) @ chol.T
            out[:, k] += noise[:, 0]
            out[:, k + 2] += noise[:, 1]
        return out

    def positions(self, particles: np.ndarray) -> np.ndarray:
        """Horizontal positions, shape (n, 2)."""
        return particles[:, :2]

    def take(self, particles: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Return the particles at ``index``."""
        return particles[index]
