"""Kalman filter on the constant-velocity state, with a hit-mixture (PDA) update.

The state is Gaussian over ``[x, y, vx, vy]`` (local frame, m and m/s); the measurement
is a hit's horizontal position with its covariance (elongated along the ray). When the
measurement model hands over several candidates as a mixture (no road hit, say), the update is the
probabilistic data association one: each hit is weighed by its likelihood under the
prediction against a clutter floor, and the weighted posteriors are merged by moment
matching, so a tree-crown hit far from the prediction barely moves the track.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hypothesiser import mahalanobis2
from .kalman_kernels import (
    predict_kernel,
    rts_positions_kernel,
    smoother_gain_kernel,
    update_kernel,
)
from .protocols import Candidates, MotionModel

__all__ = ["GaussianState", "KalmanFilter"]


@dataclass(frozen=True, eq=False)
class GaussianState:
    """A Gaussian track state.

    Parameters
    ----------
    t_s : float
        Time of the state (s).
    x : ndarray, shape (4,)
        Mean ``[x, y, vx, vy]`` (m, m/s).
    P : ndarray, shape (4, 4)
        Covariance.
    z_m : float
        Height of the last hit used (m, local frame).
    history : tuple of (float, ndarray, ndarray)
        Filtered ``(t_s, x, P)`` at the last few measurement times (oldest first), for
        the fixed-lag Rauch-Tung-Striebel smoother of :meth:`KalmanFilter.revise`.
    gains : tuple of (ndarray, ndarray)
        Smoother step ``(F, G)`` from each history entry but the newest to the next one
        (``F`` the transition over their interval, ``G = P_k F^T P_pred^-1``; each (4, 4)),
        aligned with ``history[:-1]``; computed once, when the next entry is remembered,
        since neither changes afterwards. Empty (or misaligned): :meth:`KalmanFilter.revise`
        computes them itself.
    """

    t_s: float
    x: np.ndarray
    P: np.ndarray
    z_m: float
    history: tuple[tuple[float, np.ndarray, np.ndarray], ...] = ()
    gains: tuple[tuple[np.ndarray, np.ndarray], ...] = ()


def _state(
    t_s: float,
    x: np.ndarray,
    p: np.ndarray,
    z_m: float,
    history: tuple[tuple[float, np.ndarray, np.ndarray], ...],
    gains: tuple[tuple[np.ndarray, np.ndarray], ...],
) -> GaussianState:
    """``GaussianState(t_s, x, p, z_m, history, gains)`` without the frozen-field cost.

    A live tracker makes tens of thousands of states a second (a prediction per track
    per scan); the dataclass constructor sets each field through ``object.__setattr__``.
    """
    state = object.__new__(GaussianState)
    state.__dict__.update(t_s=t_s, x=x, P=p, z_m=z_m, history=history, gains=gains)
    return state


def _kalman(x: np.ndarray, p: np.ndarray, z_xy: np.ndarray, r: np.ndarray) -> tuple:
    """One linear update with measurement covariance ``r`` (2, 2); returns (x, P).

    Joseph form keeps P symmetric positive (:func:`~.kalman_kernels.update_kernel`).
    """
    return update_kernel(x, p, z_xy, r)


@dataclass(frozen=True)
class KalmanFilter:
    """Predictor/updater for :class:`GaussianState`.

    Parameters
    ----------
    motion : MotionModel
        Linear-Gaussian motion model.
    init_speed_sigma_m_s : float
        1-sigma of each velocity component of a new track (m/s).
    clutter_density_per_m2 : float
        Density of hits that are not the object (PDA floor), 1/m^2.
    history_len : int
        Filtered states kept for :meth:`revise` (0: no smoothing).
    """

    motion: MotionModel
    init_speed_sigma_m_s: float
    clutter_density_per_m2: float = 1e-4
    history_len: int = 0

    def _remember(self, state: GaussianState) -> GaussianState:
        if self.history_len <= 0:
            return state
        gains = state.gains if len(state.gains) == len(state.history) - 1 else None
        if gains is not None and state.history:
            gains = (*gains, self._smoother_step(state.history[-1], state.t_s))
        hist = (*state.history, (state.t_s, state.x, state.P))[-self.history_len :]
        kept = gains[-(len(hist) - 1) :] if gains is not None and len(hist) > 1 else ()
        return _state(state.t_s, state.x, state.P, state.z_m, hist, kept)

    def _smoother_step(
        self, entry: tuple[float, np.ndarray, np.ndarray], t_next: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """RTS step ``(F, G)`` from a filtered history ``entry`` to time ``t_next`` (s)."""
        t_k, _, p_k = entry
        dt = t_next - t_k
        f = self.motion.transition(dt)
        return f, smoother_gain_kernel(p_k, f, self.motion.covariance(dt))

    def initiate(
        self, cands: Candidates, which: int | None, t_s: float, rng: np.random.Generator
    ) -> GaussianState:
        """Start at candidate ``which`` (None: the weighted spread of all), at rest."""
        if which is None:
            w = cands.weight
            mean = w @ cands.z_enu
            d = cands.z_enu[:, :2] - mean[:2]
            pos = np.einsum("j,jab->ab", w, cands.covariances() + d[:, :, None] * d[:, None, :])
        else:
            mean = cands.z_enu[which]
            pos = cands.cov(which)
        x = np.array([mean[0], mean[1], 0.0, 0.0])
        p = np.diag([0.0, 0.0, self.init_speed_sigma_m_s**2, self.init_speed_sigma_m_s**2])
        p[:2, :2] = pos
        return self._remember(GaussianState(t_s, x, p, float(mean[2])))

    def predict(self, state: GaussianState, t_s: float, rng: np.random.Generator) -> GaussianState:
        """Predict to ``t_s`` (never backwards)."""
        dt = max(0.0, t_s - state.t_s)
        if dt == 0.0:
            return state
        x, p = predict_kernel(
            state.x, state.P, self.motion.transition(dt), self.motion.covariance(dt)
        )
        return _state(t_s, x, p, state.z_m, state.history, state.gains)

    def gaussian(self, state: GaussianState) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal position mean (2,) and covariance (2, 2)."""
        return state.x[:2].copy(), state.P[:2, :2].copy()

    def update(
        self, state: GaussianState, cands: Candidates, chosen: int, rng: np.random.Generator
    ) -> GaussianState:
        """Update with candidate ``chosen``, or with all of them (PDA) for a mixture."""
        if not cands.mixture:
            x, p = _kalman(state.x, state.P, cands.z_enu[chosen, :2], cands.cov(chosen))
            z = float(cands.z_enu[chosen, 2])
            out = _state(state.t_s, x, p, z, state.history, state.gains)
        else:
            out = self._pda(state, cands)
        return self._remember(out)

    def _pda(self, state: GaussianState, cands: Candidates) -> GaussianState:
        m = cands.size
        lik = np.empty(m)
        xs = np.empty((m, 4))
        ps = np.empty((m, 4, 4))
        covs = cands.covariances()
        s = state.P[None, :2, :2] + covs
        d2 = mahalanobis2(s, cands.z_enu[:, :2] - state.x[None, :2])
        det = s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] * s[:, 1, 0]
        lik[:] = cands.weight * np.exp(-0.5 * d2) / (2 * np.pi * np.sqrt(det))
        for j in range(m):
            xs[j], ps[j] = _kalman(state.x, state.P, cands.z_enu[j, :2], covs[j])
        total = self.clutter_density_per_m2 + lik.sum()
        beta = lik / total
        beta0 = self.clutter_density_per_m2 / total
        x = beta0 * state.x + beta @ xs
        d0 = state.x - x
        p = beta0 * (state.P + np.outer(d0, d0))
        for j in range(m):
            dj = xs[j] - x
            p += beta[j] * (ps[j] + np.outer(dj, dj))
        best = int(np.argmax(beta))
        z = float(cands.z_enu[best, 2]) if beta[best] > beta0 else state.z_m
        return GaussianState(state.t_s, x, 0.5 * (p + p.T), z, state.history, state.gains)

    def revise(self, state: GaussianState, n: int) -> list[np.ndarray]:
        """Smooth the last ``n`` measurement times (fixed-lag Rauch-Tung-Striebel).

        Returns horizontal positions (2,), oldest first; at most ``history_len`` of them
        (none when smoothing is off). The newest equals the filtered estimate.
        """
        return list(self.revise_xy(state, n))

    def revise_xy(self, state: GaussianState, n: int) -> np.ndarray:
        """:meth:`revise` as one array, shape (r, 2) (r = 0 when smoothing is off)."""
        hist = state.history[-n:] if n > 0 else ()
        if not hist:
            return np.zeros((0, 2))
        if len(state.gains) == len(state.history) - 1:
            steps = state.gains[len(state.gains) - (len(hist) - 1) :]
        else:
            steps = tuple(
                self._smoother_step(hist[k], hist[k + 1][0]) for k in range(len(hist) - 1)
            )
        if len(hist) == 1:
            return hist[0][1][None, :2].copy()
        xs = np.array([h[1] for h in hist])
        fs = np.array([f for f, _ in steps])
        gains = np.array([g for _, g in steps])
        return rts_positions_kernel(xs, fs, gains)

    def density(self, state: GaussianState, xy: np.ndarray, cov_xy: np.ndarray) -> float:
        """Predictive density (1/m^2) of a position ``xy`` (2,) known to ``cov_xy`` (2, 2)."""
        s = state.P[:2, :2] + cov_xy
        nu = np.asarray(xy, dtype=np.float64) - state.x[:2]
        d2 = float(mahalanobis2(s, nu))
        det = float(s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0])
        return float(np.exp(-0.5 * d2) / (2.0 * np.pi * np.sqrt(det)))

    def estimate(self, state: GaussianState) -> tuple[np.ndarray, np.ndarray | None]:
        """Position (3,) and horizontal covariance (2, 2)."""
        return np.array([state.x[0], state.x[1], state.z_m]), state.P[:2, :2].copy()
