"""Initiator: tentative tracks from unassociated fixes, confirmed M-of-N style.

Every fix that no track took seeds tentative tracks: one per hit for a single-hypothesis
filter (a Kalman filter cannot hold "the crown or the road", so each hit gets its own
sibling and the siblings race), or one carrying all hits for a mixture filter (particles).
A tentative track is confirmed once it has ``m`` fixes; it is dropped if that has not
happened within ``window_s`` of its first fix (a time window rather than a scan count,
so sensors with different frame rates and fields of view count alike).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import TrackingError
from .protocols import Candidates

__all__ = ["MOfNInitiator"]


@dataclass(frozen=True)
class MOfNInitiator:
    """M fixes within a time window.

    Parameters
    ----------
    m : int
        Fixes needed to confirm (the first one included).
    window_s : float
        Time from the first fix within which they must come (s).
    per_candidate : bool
        True: one seed per hit; False: one seed with all hits.
    """

    m: int = 3
    window_s: float = 1.0
    per_candidate: bool = True

    def __post_init__(self) -> None:
        if self.m < 1 or not self.window_s > 0:
            raise TrackingError(
                f"M-of-N needs m >= 1 and window_s > 0, got {self.m}, {self.window_s}"
            )

    def seeds(self, cands: Candidates) -> list[int | None]:
        """One seed per candidate, or one for all of them."""
        if self.per_candidate:
            return list(range(cands.size))
        return [None]

    def confirmed(self, n_updates: int, age_s: float) -> bool:
        """M fixes reached."""
        return n_updates >= self.m

    def expired(self, n_updates: int, age_s: float) -> bool:
        """Window over without M fixes."""
        return age_s > self.window_s and n_updates < self.m
