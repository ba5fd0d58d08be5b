"""When each replayed scenario copy starts and how long its loop lasts.

Several scenarios (and staggered copies of each) play at once in the live replay. Two
rules keep the scene physical:

- **Commensurate loops.** Each scenario loops on a period a whole fraction of one common
  *hyper-period* (a multiple of the longest scenario's span plus gap), at most
  ``max_stretch`` longer than its own span plus gap. The streams' relative timing then
  repeats exactly every hyper-period instead of drifting from loop to loop.
- **Vehicles never overlap.** The sample scenarios share roads: started together, the car
  of one drives the same lane as a car of another, on top of it (0 m apart) for 14 s,
  which no camera could see and which the tracker can only get wrong. Copy ``k`` of a
  scenario starts ``(k + phase) / copies`` of its period after the replay's start; the
  phase of each scenario (a multiple of ``1 / candidates``) is chosen, in turn, to
  minimise the longest time any of its vehicles spends within ``min_gap_m`` of a vehicle
  of the scenarios placed before it, over a whole hyper-period. With many copies on one
  road loop, cars at different speeds must overtake somewhere: then they overlap for a
  moment (about a second), not for a whole stretch of road. Pedestrians may meet.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from demtrack.core.tracking.types import TruthPath

__all__ = ["commensurate_periods", "replay_schedule", "stagger_offsets"]

#: Time step (s) at which vehicle separations are checked.
_CHECK_DT_S = 0.05


def commensurate_periods(
    spans_s: Sequence[float], gap_s: float, max_stretch: float = 0.1, max_multiple: int = 16
) -> tuple[list[float], float]:
    """Loop periods (s) dividing one hyper-period, and that hyper-period (s).

    Scenario ``j`` needs at least ``spans_s[j] + gap_s``. The hyper-period is the
    smallest multiple (up to ``max_multiple``) of the longest need for which every
    period ``H / floor(H / need_j)`` stretches its need by at most ``max_stretch``
    (otherwise the multiple that stretches least).
    """
    needs = [max(float(s), 0.0) + gap_s for s in spans_s]
    if not needs:
        return [], 0.0
    longest = max(needs)
    best: tuple[float, float] | None = None
    for m in range(1, max_multiple + 1):
        h = m * longest
        stretch = max(h / math.floor(h / n) / n - 1.0 for n in needs)
        if best is None or stretch < best[0] - 1e-12:
            best = (stretch, h)
        if stretch <= max_stretch:
            break
    assert best is not None
    h = best[1]
    return [h / math.floor(h / n) for n in needs], h


def _positions(
    truths: Sequence[TruthPath], offsets: Sequence[float], period: float, t: np.ndarray
) -> list[np.ndarray]:
    """Each vehicle's (x, y) at replay times ``t`` for every start offset (NaN: absent)."""
    out = []
    for o in offsets:
        local = np.mod(t - o, period)
        for truth in truths:
            if truth.cls == "vehicle":
                out.append(truth.at(local)[:, :2])
    return out


def _longest_close(mine: list[np.ndarray], placed: list[np.ndarray], gap_m: float) -> int:
    """The most consecutive samples any of ``mine`` spends within ``gap_m`` of ``placed``."""
    longest = 0
    for a in mine:
        for b in placed:
            close = np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]) < gap_m  # NaN: False
            if close.any():
                edges = np.flatnonzero(np.diff(np.concatenate([[0], close.view(np.int8), [0]])))
                longest = max(longest, int(np.max(edges[1::2] - edges[0::2])))
    return longest


def stagger_offsets(
    truths: Sequence[Sequence[TruthPath]],
    periods_s: Sequence[float],
    hyper_period_s: float,
    copies: int,
    rate_hz: float,
    *,
    candidates: int = 8,
    min_gap_m: float = 1.5,
) -> list[list[float]]:
    """Start offsets (s) of each scenario's copies, whole frames (see the module doc).

    Parameters
    ----------
    truths : sequence of sequence of TruthPath
        Per scenario, its true paths (scenario time from 0).
    periods_s, hyper_period_s : from :func:`commensurate_periods`.
    copies : int
        Copies of each scenario; copy ``k`` starts ``k / copies`` of the period later.
    rate_hz : float
        Frame rate: offsets are rounded to whole frames.

    Returns
    -------
    list of list of float
        ``offsets[j][k]``: when copy ``k`` of scenario ``j`` starts (s after the
        replay's start).
    """
    t = np.arange(0.0, hyper_period_s, _CHECK_DT_S)
    placed: list[np.ndarray] = []
    out = []
    for paths, period in zip(truths, periods_s, strict=True):
        best: tuple[int, list[float], list[np.ndarray]] | None = None
        for i in range(candidates):
            offs = [
                round((k + i / candidates) * period / copies * rate_hz) / rate_hz
                for k in range(copies)
            ]
            mine = _positions(paths, offs, period, t)
            run = _longest_close(mine, placed, min_gap_m)
            if best is None or run < best[0]:
                best = (run, offs, mine)
            if run == 0:
                break
        assert best is not None
        out.append(best[1])
        placed += best[2]  # the chosen phase's positions, already computed
    return out


def replay_schedule(
    spans_s: Sequence[float],
    truths: Sequence[Sequence[TruthPath]],
    copies: int,
    rate_hz: float,
    gap_s: float,
) -> tuple[list[float], list[list[float]]]:
    """Each scenario's loop period (s) and its copies' start offsets (s): both rules.

    ``spans_s[j]``: scenario ``j``'s last frame time; ``truths[j]``: its true paths.
    """
    periods, hyper = commensurate_periods(spans_s, gap_s)
    return periods, stagger_offsets(truths, periods, hyper, copies, rate_hz)
