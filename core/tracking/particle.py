"""CONDENSATION particle filter whose likelihood is a mixture over all ray hits.

A fix that met the terrain several times does not say which hit is the object. The
likelihood of a particle at horizontal position ``x`` is therefore::

    L(x) = sum_j w_j N(x; h_j, R_j) + rho

over every hit ``h_j`` (prior weights ``w_j``, covariance ``R_j`` elongated along the
ray), plus a clutter floor ``rho`` (1/m^2) so a
fix that is none of the object's cannot wipe the particle set out. Particles near any hit
survive; several hypotheses ride along until motion disambiguates them (a tree crown
does not move like a car), so a wrong first choice never dooms a track. Resampling is
systematic, the random generator is the caller's (seeded) one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .protocols import Candidates, ParticleMotionModel

__all__ = ["ParticleFilter", "ParticleState", "mixture_likelihood", "systematic_resample"]


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Return the indices of a systematic resample of normalised ``weights`` (n,) -> (n,) int.

    One uniform offset, ``n`` evenly spaced pointers into the cumulative weights: lower
    variance than multinomial resampling, and particle ``i`` is copied either
    ``floor(n w_i)`` or ``ceil(n w_i)`` times.
    """
    n = weights.shape[0]
    pointers = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0  # guard against round-off leaving the last pointer unmatched
    return np.searchsorted(cumulative, pointers, side="right").clip(0, n - 1)


def mixture_likelihood(
    xy: np.ndarray, cands: Candidates, rho_per_m2: float, only: int | None = None
) -> np.ndarray:
    """Hit-mixture likelihood of positions ``xy`` (n, 2) -> (n,), 1/m^2.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Horizontal positions (m).
    cands : Candidates
        The hits, their sigmas and prior weights.
    rho_per_m2 : float
        Clutter floor.
    only : int or None
        Use only this candidate (weight 1) instead of the mixture.
    """
    idx = range(cands.size) if only is None else (only,)
    out = np.full(xy.shape[0], rho_per_m2)
    for j in idx:
        w = 1.0 if only is not None else float(cands.weight[j])
        r = cands.cov(j)
        det = float(r[0, 0] * r[1, 1] - r[0, 1] * r[1, 0])
        inv = np.array([[r[1, 1], -r[0, 1]], [-r[1, 0], r[0, 0]]]) / det
        d = xy - cands.z_enu[j, :2]
        d2 = np.einsum("ni,ij,nj->n", d, inv, d)
        out += w * np.exp(-0.5 * d2) / (2.0 * np.pi * np.sqrt(det))
    return out


@dataclass(frozen=True, eq=False)
class ParticleState:
    """A particle track state.

    Parameters
    ----------
    t_s : float
        Time (s).
    particles : Any
        The motion model's particle arrays.
    weights : ndarray, shape (n,)
        Normalised weights.
    z_m : float
        Height of the hit nearest the last estimate (m).
    history : tuple of ndarray, shape (n, 2) each
        Particle positions at the last few measurement times (oldest first), reindexed
        with every resampling: each particle's ancestry, from which :meth:`revise`
        re-estimates the past (the genealogy fixed-lag smoother).
    """

    t_s: float
    particles: Any
    weights: np.ndarray
    z_m: float
    history: tuple[np.ndarray, ...] = ()


@dataclass(frozen=True)
class ParticleFilter:
    """Predictor/updater for :class:`ParticleState`.

    Parameters
    ----------
    motion : ParticleMotionModel
        How particles move (free constant velocity, or along roads).
    n_particles : int
        Particles per track.
    clutter_density_per_m2 : float
        Likelihood floor ``rho``.
    resample_ess_ratio : float
        Resample when the effective sample size < this fraction of ``n_particles``.
    mode_radius_m : float
        Radius of the mode whose mean is the estimate (m).
    history_len : int
        Measurement times whose particle ancestry is kept for :meth:`revise`.
    """

    motion: ParticleMotionModel
    n_particles: int = 400
    clutter_density_per_m2: float = 1e-4
    resample_ess_ratio: float = 0.5
    mode_radius_m: float = 3.0
    history_len: int = 8

    def initiate(
        self, cands: Candidates, which: int | None, t_s: float, rng: np.random.Generator
    ) -> ParticleState:
        """Particles over all candidates (``which`` None) or around one."""
        if which is not None:
            cands = cands.take(slice(which, which + 1))
        particles = self.motion.initial(cands, self.n_particles, rng)
        weights = np.full(self.n_particles, 1.0 / self.n_particles)
        xy = self.motion.positions(particles).copy()
        return ParticleState(
            t_s, particles, weights, float(cands.weight @ cands.z_enu[:, 2]), (xy,)
        )

    def predict(self, state: ParticleState, t_s: float, rng: np.random.Generator) -> ParticleState:
        """Propagate every particle to ``t_s`` (never backwards)."""
        dt = max(0.0, t_s - state.t_s)
        if dt == 0.0:
            return state
        return ParticleState(
            t_s,
            self.motion.propagate(state.particles, dt, rng),
            state.weights,
            state.z_m,
            state.history,
        )

    def gaussian(self, state: ParticleState) -> tuple[np.ndarray, np.ndarray]:
        """Weighted mean (2,) and covariance (2, 2) of all particle positions."""
        xy = self.motion.positions(state.particles)
        w = state.weights
        mean = w @ xy
        d = xy - mean
        cov = (d * w[:, None]).T @ d + 1e-6 * np.eye(2)
        return mean, cov

    def update(
        self, state: ParticleState, cands: Candidates, chosen: int, rng: np.random.Generator
    ) -> ParticleState:
        """Weigh by the hit mixture (or the chosen hit), then resample if degenerate."""
        xy = self.motion.positions(state.particles)
        only = None if cands.mixture else chosen
        w = state.weights * mixture_likelihood(xy, cands, self.clutter_density_per_m2, only)
        w /= w.sum()
        mode, _ = self._mode(xy, w)
        near = np.argmin(np.sum((cands.z_enu[:, :2] - mode) ** 2, axis=1))
        z = float(cands.z_enu[near, 2])
        particles = state.particles
        history = (*state.history, xy.copy())[-self.history_len :]
        ess = 1.0 / float(np.sum(w * w))
        if ess < self.resample_ess_ratio * w.shape[0]:
            index = systematic_resample(w, rng)
            particles = self.motion.take(particles, index)
            history = tuple(h[index] for h in history)
            w = np.full(w.shape[0], 1.0 / w.shape[0])
        return ParticleState(state.t_s, particles, w, z, history)

    def density(self, state: ParticleState, xy: np.ndarray, cov_xy: np.ndarray) -> float:
        """Predictive density (1/m^2) of a position ``xy`` (2,) known to ``cov_xy`` (2, 2).

        The particles' weighted kernel sum: on a road network it stays concentrated on
        the roads the object could have driven, however long it was unseen.
        """
        cands = Candidates(
            np.array([[xy[0], xy[1], 0.0]]), np.ones(1), np.ones(1), False, cov_xy[None]
        )
        lik = mixture_likelihood(self.motion.positions(state.particles), cands, 0.0, only=0)
        return float(state.weights @ lik)

    def revise(self, state: ParticleState, n: int) -> list[np.ndarray]:
        """Re-estimate the last ``n`` measurement times from today's weights.

        Particles that explain every fix so far carry the right past with them: the
        mode of their ancestors' positions is the smoothed estimate (oldest first; at most
        ``history_len`` of them). A track's first fix, ambiguous alone, is settled here.
        """
        past = state.history[-n:] if n > 0 else ()
        return [self._mode(h, state.weights)[0] for h in past]

    def _mode(self, xy: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Weighted mean and covariance of the particles near the densest cell.

        The cloud may hold several hypotheses (a crown and a road 10 m apart); their
        overall mean lies between them where the object never is. Bin the particles in
        cells of ``mode_radius_m``, take the heaviest cell's centroid, and average the
        particles within ``mode_radius_m`` of it.
        """
        r = self.mode_radius_m
        cells = np.floor(xy / r).astype(np.int64)
        # one integer key per cell (1-D unique is much faster than unique over rows)
        key = (cells[:, 0] - cells[:, 0].min()) * (int(np.ptp(cells[:, 1])) + 1) + (
            cells[:, 1] - cells[:, 1].min()
        )
        keys, inverse = np.unique(key, return_inverse=True)
        mass = np.bincount(inverse, weights=w, minlength=keys.shape[0])
        top = inverse == int(np.argmax(mass))
        centre = (w[top] @ xy[top]) / w[top].sum()
        sel = np.sum((xy - centre) ** 2, axis=1) <= r * r
        ws = w[sel] / w[sel].sum()
        mean = ws @ xy[sel]
        d = xy[sel] - mean
        return mean, (d * ws[:, None]).T @ d + 1e-6 * np.eye(2)

    def estimate(self, state: ParticleState) -> tuple[np.ndarray, np.ndarray | None]:
        """Mean of the dominant mode (3,) and its horizontal covariance (2, 2)."""
        mean, cov = self._mode(self.motion.positions(state.particles), state.weights)
        return np.array([mean[0], mean[1], state.z_m]), cov
