"""Re-walks of the rare rays with more hits than a cast's first pass kept.

Each ray is walked again the way its first pass walked it (the light kernel, the angular
index of its run, or the pyramid walk), with room for all its hits, straight into its CSR
slots: the same walk, so the same hits.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _angular_kernels as _ak
from . import _hit_kernels as _hk
from . import _kernels as _k
from . import _light_kernels as _lk
from .angular_index import AngularIndex, index_arrays

__all__ = ["recast_light", "refill"]


def recast_light(
    args: tuple[Any, ...],
    threads: int,
    big: np.ndarray,
    max_hits: int,
    offsets: np.ndarray,
    range_m: np.ndarray,
    points: np.ndarray,
) -> None:
    """Light kernels' re-walk: cast rays ``big`` again with room for all their hits.

    The same walk as the first pass, so the same hits; written into their CSR slots.
    Every array has the first pass's dtype and layout: no kernel compiles for this.
    """
    o, d, rng = args[-3:]
    sub = (*args[:-3], o[big], d[big], rng[big])
    nb = len(big)
    buf = np.empty((nb, max_hits), np.float64)
    counts = np.empty(nb, np.int64)
    flags = (np.empty(nb, np.int8), np.empty(nb, bool), np.empty(nb, bool))
    _lk.cast_kernel_light(*sub, False, max_hits, threads, buf, counts, *flags)  # type: ignore[call-arg]
    sub_off = np.zeros(nb + 1, np.int64)
    np.cumsum(counts, out=sub_off[1:])
    m = int(sub_off[-1])
    sub_range = np.empty(m, np.float64)
    sub_points = np.empty((m, 3), np.float64)
    _hk.gather_hits_kernel(buf, counts, sub_off, sub[-3], sub[-2], sub_range, sub_points)
    slots = np.repeat(offsets[big] - sub_off[:-1], counts) + np.arange(m)
    range_m[slots] = sub_range
    points[slots] = sub_points


def refill(
    args: tuple[Any, ...],
    max_hits: int,
    big: np.ndarray,
    offsets: np.ndarray,
    range_m: np.ndarray,
    indexed: list[tuple[int, int, AngularIndex]],
) -> None:
    """Re-walk rays ``big`` (sorted) with all their hits, into their CSR slots.

    Rays of an indexed run take the angular walk they were cast with; the rest the
    pyramid walk. Either way the first pass's walk, so the same hits.
    """
    rest = np.ones(len(big), bool)
    for r0, r1, ix in indexed:
        i0, i1 = np.searchsorted(big, [r0, r1]).tolist()
        if i0 < i1:
            _ak.cast_angular_refill_kernel(  # type: ignore[call-arg]
                *args, max_hits, *index_arrays(ix), big[i0:i1], offsets, range_m
            )
            rest[i0:i1] = False
    if rest.any():
        left = big if rest.all() else big[rest]
        _k.cast_all_refill_kernel(*args, max_hits, left, offsets, range_m)  # type: ignore[call-arg]
