"""Hypothesiser: chi-square gate on the hit nearest a track's predicted position.

For a fix with several hits, the cost of the fix to a track is the best hit's squared
Mahalanobis distance ``d2 = nu^T (P + R)^-1 nu`` (``P`` the predicted horizontal
covariance, ``R`` the hit's, elongated along its ray). A fix none of whose hits is
inside the gate yields no hypothesis, so the track's only option for it is the missed detection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ..errors import TrackingError
from .protocols import Candidates, SingleHypothesis

__all__ = ["GatedNearestHit", "gate_d2"]


def gate_d2(probability: float) -> float:
    """Squared Mahalanobis gate holding ``probability`` of a 2-D Gaussian."""
    if not 0.0 < probability < 1.0:
        raise TrackingError(f"gate probability must be in (0, 1), got {probability}")
    return float(chi2.ppf(probability, df=2))


@dataclass(frozen=True)
class GatedNearestHit:
    """Gate and score by the candidate nearest the prediction.

    Parameters
    ----------
    gate_d2 : float
        Squared Mahalanobis distance threshold (see :func:`gate_d2`).
    """

    gate_d2: float

    def distances2(self, mean_xy: np.ndarray, cov_xy: np.ndarray, cands: Candidates) -> np.ndarray:
        """Squared Mahalanobis distance of every candidate, shape (m,)."""
        out = np.empty(cands.size)
        for j in range(cands.size):
            s = cov_xy + cands.cov(j)
            nu = cands.z_enu[j, :2] - mean_xy
            out[j] = float(nu @ np.linalg.solve(s, nu))
        return out

    def hypothesise(
        self, mean_xy: np.ndarray, cov_xy: np.ndarray, cands: Candidates, measurement_index: int
    ) -> SingleHypothesis | None:
        """Return the best candidate's hypothesis, or None when every candidate is outside."""
        d2 = self.distances2(mean_xy, cov_xy, cands)
        j = int(np.argmin(d2))
        if not d2[j] <= self.gate_d2:
            return None
        return SingleHypothesis(measurement_index, j, float(d2[j]))
