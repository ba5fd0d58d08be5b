"""The raw "filter": a track point is the measurement itself (baselines raw-first, last-hit).

No smoothing: the track goes wherever the chosen hit is, which is what the baselines are
meant to show. So that the baselines differ from the filters only in that, association
still predicts with a constant-velocity Kalman filter fed the same raw hits, gated
``gate_m`` wide around it (a tree-crown hit is accepted, as the baseline would).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .kalman import GaussianState, KalmanFilter
from .protocols import Candidates

__all__ = ["PassThroughFilter", "RawState"]


@dataclass(frozen=True, eq=False)
class RawState:
    """Last measured position and the association predictor's state.

    Parameters
    ----------
    t_s : float
        Time of the state (s).
    predictor : GaussianState
        Constant-velocity state fed the raw hits (for association only).
    p_enu : ndarray, shape (3,)
        Last measured position (m).
    sigma_m : float
        Its 1-sigma horizontal uncertainty (m).
    """

    t_s: float
    predictor: GaussianState
    p_enu: np.ndarray
    sigma_m: float


@dataclass(frozen=True)
class PassThroughFilter:
    """Predictor/updater for :class:`RawState`.

    Parameters
    ----------
    predictor : KalmanFilter
        Association predictor.
    gate_m : float
        Association radius around its prediction (m).
    gate_d2 : float
        The hypothesiser's chi-square gate, so the radius maps to a covariance.
    """

    predictor: KalmanFilter
    gate_m: float
    gate_d2: float

    def initiate(
        self, cands: Candidates, which: int | None, t_s: float, rng: np.random.Generator
    ) -> RawState:
        """Start at candidate ``which`` (None: the first)."""
        j = 0 if which is None else which
        kf = self.predictor.initiate(cands, j, t_s, rng)
        return RawState(t_s, kf, cands.z_enu[j].copy(), float(cands.sigma_m[j]))

    def predict(self, state: RawState, t_s: float, rng: np.random.Generator) -> RawState:
        """Keep the measured position; move the predictor on."""
        kf = self.predictor.predict(state.predictor, t_s, rng)
        return replace(state, t_s=kf.t_s, predictor=kf)

    def gaussian(self, state: RawState) -> tuple[np.ndarray, np.ndarray]:
        """Predicted position, covariance widened by the association radius."""
        mean, cov = self.predictor.gaussian(state.predictor)
        return mean, cov + (self.gate_m**2 / self.gate_d2) * np.eye(2)

    def update(
        self, state: RawState, cands: Candidates, chosen: int, rng: np.random.Generator
    ) -> RawState:
        """Take the chosen candidate as is."""
        single = replace(cands, mixture=False)
        kf = self.predictor.update(state.predictor, single, chosen, rng)
        return RawState(state.t_s, kf, cands.z_enu[chosen].copy(), float(cands.sigma_m[chosen]))

    def density(self, state: RawState, xy: np.ndarray, cov_xy: np.ndarray) -> float:
        """Zero: the raw methods never carry an identity across a lost spell."""
        return 0.0

    def revise(self, state: RawState, n: int) -> list[np.ndarray]:
        """No retrospective estimates (an empty list): past points stand as measured."""
        return []

    def estimate(self, state: RawState) -> tuple[np.ndarray, np.ndarray | None]:
        """Return the measured position and ``sigma^2 I``."""
        return state.p_enu.copy(), state.sigma_m**2 * np.eye(2)
