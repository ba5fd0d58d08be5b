"""Deleter: a confirmed track ends after coasting too long.

Below the limit a track coasts on its motion model with growing uncertainty, which is
what keeps its identity through a short occlusion or a hand-off between cameras.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from ..errors import TrackingError

__all__ = ["CoastTimeDeleter"]


@dataclass(frozen=True)
class CoastTimeDeleter:
    """Delete after ``max_coast_s[cls]`` seconds without a fix.

    Parameters
    ----------
    max_coast_s : mapping of str to float
        Coast limit per class (s).
    """

    max_coast_s: Mapping[str, float]

    def delete(self, cls: str, coast_s: float) -> bool:
        """Whether the track ends."""
        try:
            limit = self.max_coast_s[cls]
        except KeyError:
            raise TrackingError(f"no coast limit for class {cls!r}") from None
        return coast_s > limit
