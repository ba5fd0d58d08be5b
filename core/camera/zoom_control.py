"""Automatic zoom while following: keep the target's image width in a band.

A following head zooms so that its target spans a share of the image width inside a
band (default 5-14 %): wide enough to see it turn, narrow enough to see it well. The
rule (:func:`zoom_to_band`) is a hold-or-rescale one with hysteresis: while the share is
inside the band the zoom holds; once it leaves, the new field of view is the current one
scaled by ``share / goal`` (the share of a small object is nearly proportional to
``1 / hfov``), so the target comes back to the band's ``goal`` (default 8 %), and it is
held inside the head's and the lens's field-of-view range. The head's zoom rate limits
how fast it gets there (:mod:`~demtrack.core.camera.head_motion`).

The share comes from a measured box (the sample site's scenarios,
``demtrack.samplesite.active_follow``) or from the target's range and a nominal size
(:func:`image_share`; the server's controller, which sees tracks, not boxes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import PoseError

__all__ = ["ZoomBand", "image_share", "zoom_to_band"]


@dataclass(frozen=True)
class ZoomBand:
    """The target's share of the image width a follower keeps (fractions of the width).

    Parameters
    ----------
    lo, hi : float
        The band: the zoom holds while the share is inside ``[lo, hi]``.
    goal : float
        The share a zoom change aims for, inside the band.

    Raises
    ------
    PoseError
        Unless ``0 < lo <= goal <= hi <= 1``.
    """

    lo: float = 0.05
    hi: float = 0.14
    goal: float = 0.08

    def __post_init__(self) -> None:
        values = (self.lo, self.goal, self.hi)
        if (
            not all(math.isfinite(x) for x in values)
            or not 0.0 < self.lo <= self.goal <= self.hi <= 1.0
        ):
            raise PoseError(
                f"a zoom band needs 0 < lo <= goal <= hi <= 1, got lo={self.lo}, "
                f"goal={self.goal}, hi={self.hi}"
            )


def zoom_to_band(
    hfov_deg: float,
    share: float | None,
    band: ZoomBand,
    hfov_range_deg: tuple[float, float],
) -> float:
    """The field of view (degrees) to command for a target spanning ``share`` of the width.

    Parameters
    ----------
    hfov_deg : float
        The head's present horizontal field of view (degrees).
    share : float or None
        The target's width as a share of the image width at ``hfov_deg``; None (not
        measured): hold.
    band : ZoomBand
    hfov_range_deg : tuple of 2 float
        ``(narrowest, widest)`` field of view allowed (degrees): the head's limits and the
        lens's calibrated range together.

    Returns
    -------
    float
        ``hfov_deg`` while the share is in the band (held as it is), else
        ``hfov_deg * share / band.goal`` held within ``hfov_range_deg``.
    """
    if share is None or not math.isfinite(share) or band.lo <= share <= band.hi:
        return float(hfov_deg)
    lo, hi = hfov_range_deg
    return float(min(max(hfov_deg * share / band.goal, lo), hi))


def image_share(size_m: float, range_m: float, fx_px: float, width_px: int) -> float:
    """Share of the image width an object ``size_m`` across at ``range_m`` spans.

    The pinhole's ``fx * size / range`` pixels (an object small against its range, near
    the image centre, which a follower keeps it at), over ``width_px``.
    """
    return float(fx_px * size_m / max(float(range_m), 1e-6) / width_px)
