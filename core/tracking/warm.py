"""Compile the tracker's numba kernels by tracking a tiny two-camera scene.

The kernels (:mod:`~demtrack.core.tracking.fusion_kernels`,
:mod:`~demtrack.core.tracking.kalman_kernels`,
:mod:`~demtrack.core.tracking.hypothesiser_kernels`) are compiled for the exact argument types
the tracker passes (read-only fix arrays, cached read-only motion matrices, ...), so the
surest warm-up is the tracker itself on a few fixes: an object walking in front of two
cameras, each fix with a terrain hit and a tree-crown hit and full covariances. About
10 s of CPU with an empty numba cache, well under a second from it.
"""

from __future__ import annotations

import numpy as np

from .methods import run_tracker
from .types import Fix

__all__ = ["PARTS", "warm_up"]


def _walk() -> list[Fix]:
    cams = {"a": np.array([-60.0, 0.0, 15.0]), "b": np.array([0.0, -70.0, 18.0])}
    cov = np.array([[[0.3, 0.05], [0.05, 0.6]], [[2.0, 0.0], [0.0, 2.0]]])
    fixes: list[Fix] = []
    for k in range(16):
        target = np.array([0.8 * k, 0.4 * k, 0.0])
        for name, origin in cams.items():
            crown = target + [2.0, -1.5, 4.0]
            fixes.append(
                Fix(
                    0.5 * k,
                    name,
                    "human",
                    len(fixes),
                    origin,
                    target - origin,
                    np.array([crown, target]),
                    np.array([1.4, 0.6]),
                    hit_cov_en_m2=cov,
                )
            )
    return fixes


#: Parts of the walk, for compiling its kernels in separate processes: ``fusion`` is the
#: first step's pair of fixes (fused, a track started with nothing to predict yet),
#: ``kalman`` what one camera sees (no pair to fuse, every Kalman and gating kernel).
#: Together they compile exactly what the whole walk compiles.
PARTS = ("all", "fusion", "kalman")


def warm_up(method: str = "kalman", part: str = "all") -> None:
    """Track the tiny walk (or a :data:`PARTS` share of it) with ``method``."""
    fixes = _walk()
    if part == "fusion":
        fixes = [f for f in fixes if f.t_s == 0.0]
    elif part == "kalman":
        fixes = [f for f in fixes if f.sensor == "a"]
    elif part != "all":
        raise ValueError(f"unknown warm-up part {part!r}: want one of {', '.join(PARTS)}")
    run_tracker(fixes, method)
