"""Initiator: tentative tracks from unassociated fixes, confirmed M-of-N and once settled.

Every fix that no track took seeds tentative tracks: one per hit for a single-hypothesis
filter (a Kalman filter cannot hold "the crown or the road", so each hit gets its own
sibling and the siblings race), or one carrying all hits for a mixture filter (particles).
A tentative track is confirmed once it has ``m`` fixes *and* its position is settled: the
worst-direction 1-sigma of its state's position (the whole state, so a particle cloud
still split between a crown and a road is not settled) is at most ``max_spread_m``, or
once ``settle_window_s`` has passed since its first fix (an object only ever seen poorly
is still an object). It is dropped if it has not reached ``m`` fixes within ``window_s``
of its first fix (a time window rather than a scan count, so sensors with different
frame rates and fields of view count alike).

Why settle: one far camera looking along a road gives fixes several metres apart along
its rays; a track confirmed on three of them starts metres off, and the first seconds of
its path are drawn where the object never was. Waiting until motion has pinned the state
(and reporting the points made before that only where they were already settled, see
:meth:`MOfNInitiator.reportable`) costs a second or two of coverage instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import TrackingError
from .protocols import Candidates

__all__ = ["MOfNInitiator", "spread_m"]


def spread_m(cov_xy: np.ndarray) -> float:
    """Worst-direction 1-sigma (m) of a horizontal covariance (2, 2) (m^2)."""
    cov = np.asarray(cov_xy, dtype=np.float64)
    return math.sqrt(max(float(np.linalg.eigvalsh(0.5 * (cov + cov.T))[-1]), 0.0))


@dataclass(frozen=True)
class MOfNInitiator:
    """M fixes within a time window, then a settled position.

    Parameters
    ----------
    m : int
        Fixes needed to confirm (the first one included).
    window_s : float
        Time from the first fix within which they must come (s).
    per_candidate : bool
        True: one seed per hit; False: one seed with all hits.
    max_spread_m : float or None
        Confirm only when the state's worst-direction position 1-sigma is at most this
        (m); None: M fixes suffice (the plain M-of-N rule).
    settle_window_s : float
        A tentative track with ``m`` fixes is confirmed this long after its first fix
        even if it has not settled (s; at least ``window_s``).
    """

    m: int = 3
    window_s: float = 1.0
    per_candidate: bool = True
    max_spread_m: float | None = None
    settle_window_s: float = 5.0

    def __post_init__(self) -> None:
        if self.m < 1 or not self.window_s > 0:
            raise TrackingError(
                f"M-of-N needs m >= 1 and window_s > 0, got {self.m}, {self.window_s}"
            )
        if self.max_spread_m is not None and not (
            math.isfinite(self.max_spread_m) and self.max_spread_m > 0
        ):
            raise TrackingError(f"max_spread_m must be positive or None, got {self.max_spread_m}")
        if not (math.isfinite(self.settle_window_s) and self.settle_window_s >= self.window_s):
            raise TrackingError(
                f"settle_window_s must be >= window_s ({self.window_s}), got {self.settle_window_s}"
            )

    def seeds(self, cands: Candidates) -> list[int | None]:
        """One seed per candidate, or one for all of them."""
        if self.per_candidate:
            return list(range(cands.size))
        return [None]

    def settled(self, spread: float) -> bool:
        """Whether a position known to ``spread`` (m, worst-direction 1-sigma) is settled."""
        return self.max_spread_m is None or spread <= self.max_spread_m

    def confirmed(self, n_updates: int, age_s: float, spread: float = 0.0) -> bool:
        """M fixes reached, and the position settled or the settle window over.

        ``spread``: the state's worst-direction position 1-sigma (m, :func:`spread_m`).
        """
        if n_updates < self.m:
            return False
        return self.settled(spread) or age_s >= self.settle_window_s

    def expired(self, n_updates: int, age_s: float) -> bool:
        """Window over without M fixes."""
        return age_s > self.window_s and n_updates < self.m

    def reportable(self, spreads: list[float]) -> int:
        """How many leading points of a newly confirmed track to leave out.

        ``spreads`` are the state's spreads (m) when each tentative point was made,
        oldest first. The points before the first settled one are left out: they were
        guesses the filter itself did not trust (the smoother revises the rest). A track
        that never settled keeps only its newest point (the caller's business).
        """
        for k, s in enumerate(spreads):
            if self.settled(s):
                return k
        return len(spreads)
