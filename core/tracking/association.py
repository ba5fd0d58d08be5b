"""Data associator: global nearest neighbour with explicit missed detections.

The assignment problem is augmented so that "missed" is a column like any other::

                 measurements (M)        missed (T)
    tracks (T)   [ d2 or forbidden  |  gate on diagonal ]
    unused (M)   [ 0 on diagonal    |  0                ]

and solved with :func:`scipy.optimize.linear_sum_assignment`. A track takes a
measurement only when that is cheaper than missing (the gate) - never two tracks one
measurement, never one track two.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .protocols import Hypothesis, MissedDetection, SingleHypothesis

__all__ = ["GlobalNearestNeighbour"]

_FORBIDDEN = 1e18


@dataclass(frozen=True)
class GlobalNearestNeighbour:
    """GNN associator.

    Parameters
    ----------
    miss_cost : float
        Cost of the missed-detection hypothesis (the squared gate).
    """

    miss_cost: float

    def associate(
        self, hypotheses: Sequence[Sequence[SingleHypothesis | None]], n_measurements: int
    ) -> list[Hypothesis]:
        """One hypothesis per track, minimising the total cost."""
        n_tracks = len(hypotheses)
        if n_tracks == 0:
            return []
        m = n_measurements
        quick = _obvious(hypotheses, self.miss_cost)
        if quick is not None:
            return quick
        cost = np.full((n_tracks + m, m + n_tracks), _FORBIDDEN)
        for i, row in enumerate(hypotheses):
            for j, hyp in enumerate(row):
                if hyp is not None:
                    cost[i, j] = hyp.distance2
            cost[i, m + i] = self.miss_cost
        cost[n_tracks:, :m][np.diag_indices(m)] = 0.0
        cost[n_tracks:, m:] = 0.0
        rows, cols = linear_sum_assignment(cost)
        out: list[Hypothesis] = [MissedDetection()] * n_tracks
        for r, c in zip(rows, cols, strict=True):
            if r < n_tracks and c < m and cost[r, c] < _FORBIDDEN:
                hyp = hypotheses[r][c]
                if hyp is not None:
                    out[r] = hyp
        return out


def _obvious(
    hypotheses: Sequence[Sequence[SingleHypothesis | None]], miss_cost: float
) -> list[Hypothesis] | None:
    """The assignment when it needs no solver (None when it does).

    When no two tracks gate the same measurement the tracks do not compete, and the
    optimum is each track's own: its cheapest hypothesis where that is strictly cheaper
    than missing and than its others, else the missed detection. A tie (or a shared
    measurement) goes to the solver, which settles it its own way.
    """
    seen: set[int] = set()
    out: list[Hypothesis] = []
    for row in hypotheses:
        real = []
        for j, h in enumerate(row):
            if h is not None:
                if j in seen:
                    return None
                seen.add(j)
                real.append(h)
        if not real:
            out.append(MissedDetection())
            continue
        best = min(real, key=_distance2)
        d = best.distance2
        if d == miss_cost or sum(1 for h in real if h.distance2 <= d) != 1:
            return None
        out.append(best if d < miss_cost else MissedDetection())
    return out


def _distance2(h: SingleHypothesis) -> float:
    return h.distance2
